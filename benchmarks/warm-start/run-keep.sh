#!/bin/sh
# surge (KEEP: FAST with keep=2, chosen on validation data in benchmarks/rollout-variants/) on the warm-start protocol
# of run.sh; FAST, without keep, is surge:keep=none (these files record no keep). The same instances, every other row
# borrowed from results-*.json (not run again). Each policy starts hour h where it left the fleet after driving hour h-1
# from the seed's random start. Seeds come in rounds (ROUNDS, default "5 10"), both maps in turn; a rerun resumes.
# To run this script again, name every label in full: see "Labels" in benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../.."
OUT=benchmarks/warm-start
SURGE=${SURGE:-surge}
FAST=surge:base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1
KEEP=$FAST,keep=2
for N in ${ROUNDS:-5 10}; do
  for S in nyc synthetic; do
    $SURGE evaluate --warm-start --scenario "$S" --data ../shared/data --date 2022-11-17 --hours 17 19 --seeds "$N" --taxis 100 \
      --minutes 60 --forecast previous-hour --policies greedy rebalance match "$FAST" "$KEEP" --jobs 2 \
      --json "$OUT/keep-$S.json" --resume --borrow "$OUT/results-$S.json" > "$OUT/summary-keep-$S.txt.tmp"
    mv "$OUT/summary-keep-$S.txt.tmp" "$OUT/summary-keep-$S.txt"
  done
done
