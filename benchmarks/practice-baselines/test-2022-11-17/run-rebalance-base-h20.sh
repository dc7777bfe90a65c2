#!/bin/sh
# surge rolled out over rebalance with a 20-minute horizon (base=rebalance, scope=map, horizon=20), the setting
# chosen on validation data (benchmarks/rollout-variants/), added to the test-date files of run.sh and
# run-real-level.sh: the same instances, previous-hour demand for every policy; a resumed run computes only the
# new label. The synthetic city first (10 seeds at 17 and 19 h), then the real map seed by seed at its four hours.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-2022-11-17
OLD=surge:base=rebalance,scope=map
NEW=surge:base=rebalance,scope=map,horizon=20
surge evaluate --scenario synthetic --data "$(cd ../shared/data && pwd)" --date 2022-11-17 --hours 17 19 --seeds 10 --taxis 100 --minutes 60 \
    --forecast previous-hour --policies greedy ia surge match rebalance "$OLD" "$NEW" --jobs 2 --json "$OUT/results-synthetic.json" --resume \
  > "$OUT/summary-synthetic.txt"
for N in 3 5; do
  surge evaluate --scenario nyc --data ../shared/data --date 2022-11-17 --hours 15 17 19 21 --seeds "$N" --taxis 100 --minutes 60 \
      --forecast previous-hour --policies greedy ia surge match rebalance "$OLD" "$NEW" --jobs 2 --json "$OUT/results-nyc-real-level.json" --resume \
    > "$OUT/summary-nyc-real-level.txt"
done
