#!/bin/sh
# Fleet-size sweep for surge with keep=2 (KEEP, named in full; chosen on validation data in benchmarks/rollout-variants/)
# and its three forecasts: previous-hour demand, the true rates and the trained model of each map. Each regime writes
# keep-<map>-<taxis>.json; the rows of greedy, rebalance, match and surge without keep (FAST) are borrowed from
# default-<map>-<taxis>.json (same settings), so only KEEP's rows run.
# Seeds come in rounds (ROUNDS, default "5 10"), each regime in turn; a rerun resumes. SURGE overrides the command
# (default: surge); JOBS the parallel episodes (default 1).
set -e
cd "$(dirname "$0")/../.."
OUT=benchmarks/fleet-size
FAST=surge:base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1
KEEP=$FAST,keep=2
SURGE=${SURGE:-surge}
for N in ${ROUNDS:-5 10}; do
  for T in 100 150 200; do
    for S in synthetic nyc; do
      if [ "$S" = synthetic ]; then M=benchmarks/paper-protocol/full-synthetic/model; else M=$OUT/nyc-model; fi
      $SURGE evaluate --scenario "$S" --data ../shared/data --date 2022-11-17 --hours 17 19 --seeds "$N" --taxis "$T" --minutes 60 \
        --forecast previous-hour --policies greedy rebalance match "$FAST" "$KEEP" "$KEEP,forecast=true-rate" "$KEEP,forecast=model,model=$M" \
        --jobs "${JOBS:-1}" --borrow "$OUT/default-$S-$T.json" --json "$OUT/keep-$S-$T.json" --resume \
        > "$OUT/summary-keep-$S-$T.txt.tmp" 2>> "$OUT/run.log"
      mv "$OUT/summary-keep-$S-$T.txt.tmp" "$OUT/summary-keep-$S-$T.txt"
    done
  done
done
