#!/bin/sh
# Fleet-size sweep: 100, 150 and 200 taxis on the same demand (the paper's test date, 17 and 19 h, both maps),
# every policy with previous-hour demand, and the greedy rollout (a bare `surge` in these files, which record it as
# surge's defaults) also with the true rates and the trained model of each map. FAST is today's default surge, named
# in full: a bare `surge` here would not resume these files.
# Seeds come in rounds (1, 2, 3, 6, 10; ROUNDS overrides, e.g. ROUNDS="4 5 6"), each regime in turn, so that a run cut
# short holds whole seeds in every regime.
# The 100-taxi rows of the practice-baselines main table have the same settings: they are borrowed, not run again.
# SURGE overrides the command (default: surge), e.g. SURGE="python -m coordinator.cli"; JOBS the parallel episodes (default 1).
# To rerun these files under today's defaults see "Labels" in benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../.."
OUT=benchmarks/fleet-size
PRACTICE=benchmarks/practice-baselines/test-2022-11-17
FAST=surge:base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1
MODEL=benchmarks/paper-protocol/full-synthetic/model
MODEL_NYC=benchmarks/fleet-size/nyc-model
SURGE=${SURGE:-surge}
for N in ${ROUNDS:-1 2 3 6 10}; do
  for T in 150 200 100; do
    for S in synthetic nyc; do
      if [ "$S" = synthetic ]; then EXTRA="surge:forecast=model,model=$MODEL"; LEND=$PRACTICE/fast-synthetic.json
      else EXTRA="surge:forecast=model,model=$MODEL_NYC"; LEND=$PRACTICE/fast-nyc.json; fi
      BORROW=""; [ "$T" = 100 ] && BORROW="--borrow $LEND"
      $SURGE evaluate --scenario "$S" --data ../shared/data --date 2022-11-17 --hours 17 19 --seeds "$N" --taxis "$T" --minutes 60 \
        --forecast previous-hour --policies greedy rebalance match surge surge:forecast=true-rate $EXTRA "$FAST" --jobs "${JOBS:-1}" \
        --json "$OUT/results-$S-$T.json" --resume $BORROW > "$OUT/summary-$S-$T.txt.tmp" 2>> "$OUT/run.log"
      mv "$OUT/summary-$S-$T.txt.tmp" "$OUT/summary-$S-$T.txt"
    done
  done
done
