#!/bin/sh
# The warm-start protocol on the paper's test date: each policy starts hour h where it left the fleet after driving
# hour h-1 from the seed's random start. 17 and 19 h, 100 taxis, both maps, previous-hour demand for every policy.
# Seeds come in rounds (1, 3, 6, 10) on both maps in turn, so that a run cut short holds whole seeds on both.
# SURGE overrides the command (default: surge), e.g. SURGE="python -m coordinator.cli". A bare `surge` in these files is the
# greedy rollout (they record it as surge's defaults); FAST, named in full, is surge:keep=none (the files record no keep).
# surge itself (FAST,keep=2) runs in run-keep.sh. To run this script again, name every label in full: see "Labels" in
# benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../.."
OUT=benchmarks/warm-start
SURGE=${SURGE:-surge}
FAST=surge:base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1
for N in 1 3 6 10; do
  for S in synthetic nyc; do
    $SURGE evaluate --warm-start --scenario "$S" --data ../shared/data --date 2022-11-17 --hours 17 19 --seeds "$N" --taxis 100 \
      --minutes 60 --forecast previous-hour --policies greedy rebalance match surge "$FAST" --jobs 2 \
      --json "$OUT/results-$S.json" --resume > "$OUT/summary-$S.txt.tmp" 2>> "$OUT/run.log"
    mv "$OUT/summary-$S.txt.tmp" "$OUT/summary-$S.txt"
  done
done
