#!/bin/sh
# The main table: surge against the practical baselines on the paper's date, 25 seeds at each of its
# four hours, both maps (the real map at the real 2022 level of each hour), previous-hour demand for
# every policy. Rows that run.sh and run-real-level.sh already hold are borrowed, not run again.
# Seeds are added in rounds so that a run cut short holds whole seeds at every hour on both maps.
# A bare `surge` in these files is the greedy rollout, as they record; to rerun them under today's defaults see
# "Labels" in benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-2022-11-17
for N in 15 20 25; do
  surge evaluate --scenario synthetic --date 2022-11-17 --hours 15 17 19 21 --seeds "$N" --taxis 100 --minutes 60 \
    --forecast previous-hour --policies greedy ia surge match rebalance --jobs 2 --json "$OUT/main-synthetic.json" --resume \
    --borrow "$OUT/results-synthetic.json" > "$OUT/summary-main-synthetic.txt.tmp"
  mv "$OUT/summary-main-synthetic.txt.tmp" "$OUT/summary-main-synthetic.txt"
  surge evaluate --scenario nyc --data ../shared/data --date 2022-11-17 --hours 15 17 19 21 --seeds "$N" --taxis 100 --minutes 60 \
    --forecast previous-hour --policies greedy ia surge match rebalance --jobs 2 --json "$OUT/main-nyc.json" --resume \
    --borrow "$OUT/results-nyc-real-level.json" > "$OUT/summary-main-nyc.txt.tmp"
  mv "$OUT/summary-main-nyc.txt.tmp" "$OUT/summary-main-nyc.txt"
done
