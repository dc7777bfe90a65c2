#!/bin/sh
# surge against the practical baselines on the real map at the real 2022 level of each hour (the
# hourly Manhattan totals), on the paper's date, its four hours, previous-hour demand for every policy.
# A bare `surge` in these files is the greedy rollout, as they record; to rerun them under today's defaults see
# "Labels" in benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-2022-11-17
surge evaluate --scenario nyc --data ../shared/data --date 2022-11-17 --hours 15 17 19 21 --seeds 10 --taxis 100 --minutes 60 \
  --forecast previous-hour --policies greedy ia surge match rebalance --jobs 2 --json "$OUT/results-nyc-real-level.json" --resume \
  > "$OUT/summary-nyc-real-level.txt.tmp"
mv "$OUT/summary-nyc-real-level.txt.tmp" "$OUT/summary-nyc-real-level.txt"
