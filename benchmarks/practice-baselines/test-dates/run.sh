#!/bin/sh
# surge against the practical baselines on two further test-month dates, Thursdays like the paper's
# (2022-10-20 and 2022-12-08, chosen before any run), 10 seeds at 17 and 19 h, both maps (the real map
# at the real 2022 level of each hour), previous-hour demand for every policy.
# Seeds are added in rounds so that a run cut short holds whole seeds on both dates and maps.
# A bare `surge` in these files is the greedy rollout, as they record; to rerun them under today's defaults see
# "Labels" in benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-dates
for N in 5 10; do
  for S in synthetic nyc; do
    surge evaluate --scenario "$S" --data ../shared/data --dates 2022-10-20 2022-12-08 --hours 17 19 --seeds "$N" --taxis 100 \
      --minutes 60 --forecast previous-hour --policies greedy ia surge match rebalance --jobs 2 --json "$OUT/results-$S.json" --resume \
      > "$OUT/summary-$S.txt.tmp"
    mv "$OUT/summary-$S.txt.tmp" "$OUT/summary-$S.txt"
  done
done
