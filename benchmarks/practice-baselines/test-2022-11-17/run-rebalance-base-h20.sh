#!/bin/sh
# surge rolled out over rebalance with a 20-minute horizon (base=rebalance, scope=map, horizon=20), the setting
# chosen on validation data (benchmarks/rollout-variants/), at the four hours of the paper's date on both maps:
# the main table's instances and rows (borrowed from main-*.json, not run again), previous-hour demand for every
# policy. The label's first rows, run beside the 10-minute rollout, are borrowed from results-*.json. Seeds are
# added in rounds (ROUNDS, default "5 7 10") so that a run cut short holds whole seeds at every hour; a rerun resumes.
# FAST is the same rollout with three approximations that plan it about 6 times faster (samples=200, cap=12,
# adaptive=1; benchmarks/rollout-variants/ measures what they cost on validation data); these files record no keep, so
# FAST in them is surge:keep=none.
# A bare `surge` in these files is the greedy rollout, as they record; to rerun them under today's defaults see
# "Labels" in benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-2022-11-17
NEW=surge:base=rebalance,scope=map,horizon=20
FAST=$NEW,samples=200,cap=12,adaptive=1
BASE="greedy ia surge match rebalance"
add() {  # map, seeds, results file the label's rows are borrowed from
  surge evaluate --scenario "$1" --data ../shared/data --date 2022-11-17 --hours 15 17 19 21 --seeds "$2" --taxis 100 \
      --minutes 60 --forecast previous-hour --policies $BASE "$NEW" "$FAST" --jobs 2 --json "$OUT/h20-$1.json" --resume \
      --borrow "$3" > "$OUT/summary-h20-$1.txt.tmp"
  mv "$OUT/summary-h20-$1.txt.tmp" "$OUT/summary-h20-$1.txt"
}
for MAP in synthetic nyc; do
  [ -e "$OUT/h20-$MAP.json" ] || surge evaluate --scenario "$MAP" --data ../shared/data --date 2022-11-17 --hours 15 17 19 21 \
      --seeds 10 --taxis 100 --minutes 60 --forecast previous-hour --policies $BASE --jobs 2 --json "$OUT/h20-$MAP.json" \
      --borrow "$OUT/main-$MAP.json" > /dev/null
done
for N in ${ROUNDS:-5 7 10}; do
  add synthetic "$N" "$OUT/results-synthetic.json"
  add nyc "$N" "$OUT/results-nyc-real-level.json"
done
