#!/bin/sh
# surge rolled out over rebalance with a 20-minute horizon (base=rebalance, scope=map, horizon=20, the setting chosen
# on validation data) on the further test dates of run.sh: the same instances, the other policies' rows borrowed from
# results-*.json (not run again), previous-hour demand for every policy. Seeds come in rounds (ROUNDS, default
# "3 5 10"), each map in turn, so that a run cut short holds whole seeds on both dates; a rerun resumes. The same
# rollout with samples=200,cap=12,adaptive=1 (FAST, about 6 times faster; see benchmarks/rollout-variants/) runs beside
# it; these files record no keep, so FAST in them is surge:keep=none.
# A bare `surge` in these files is the greedy rollout, as they record; to rerun them under today's defaults see
# "Labels" in benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-dates
NEW=surge:base=rebalance,scope=map,horizon=20
FAST=$NEW,samples=200,cap=12,adaptive=1
for N in ${ROUNDS:-3 5 10}; do
  for S in synthetic nyc; do
    surge evaluate --scenario "$S" --data ../shared/data --dates 2022-10-20 2022-12-08 --hours 17 19 --seeds "$N" --taxis 100 \
      --minutes 60 --forecast previous-hour --policies greedy ia surge match rebalance "$NEW" "$FAST" \
      --jobs 2 --json "$OUT/h20-$S.json" --resume --borrow "$OUT/results-$S.json" > "$OUT/summary-h20-$S.txt.tmp"
    mv "$OUT/summary-h20-$S.txt.tmp" "$OUT/summary-h20-$S.txt"
  done
done
