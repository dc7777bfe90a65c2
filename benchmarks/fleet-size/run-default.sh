#!/bin/sh
# Fleet-size sweep for today's default surge (FAST, named in full) with its three forecasts: previous-hour demand,
# the true rates and the trained model of each map. Each regime writes default-<map>-<taxis>.json; the rows of
# greedy, rebalance, match and FAST with previous-hour demand are borrowed from run.sh's results-<map>-<taxis>.json
# (same settings), so the new episodes are FAST with the true rates and with the model.
# Seeds come in rounds (ROUNDS, default "3 6 10"), each regime in turn, so that a run cut short holds whole seeds
# in every regime. SURGE overrides the command (default: surge); JOBS the parallel episodes (default 1).
set -e
cd "$(dirname "$0")/../.."
OUT=benchmarks/fleet-size
FAST=surge:base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1
SURGE=${SURGE:-surge}
for N in ${ROUNDS:-3 6 10}; do
  for T in 100 150 200; do
    for S in synthetic nyc; do
      if [ "$S" = synthetic ]; then M=benchmarks/paper-protocol/full-synthetic/model; else M=$OUT/nyc-model; fi
      $SURGE evaluate --scenario "$S" --data ../shared/data --date 2022-11-17 --hours 17 19 --seeds "$N" --taxis "$T" --minutes 60 \
        --forecast previous-hour --policies greedy rebalance match "$FAST" "$FAST,forecast=true-rate" "$FAST,forecast=model,model=$M" \
        --jobs "${JOBS:-1}" --borrow "$OUT/results-$S-$T.json" --json "$OUT/default-$S-$T.json" --resume \
        > "$OUT/summary-default-$S-$T.txt.tmp" 2>> "$OUT/run.log"
      mv "$OUT/summary-default-$S-$T.txt.tmp" "$OUT/summary-default-$S-$T.txt"
    done
  done
done
