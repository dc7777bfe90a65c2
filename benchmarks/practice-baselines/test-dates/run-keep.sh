#!/bin/sh
# surge (KEEP: FAST with keep=2, the base policy's control unless a candidate beats it by more than 2 standard errors;
# keep=2 chosen on validation data in benchmarks/rollout-variants/) on the further test dates of run.sh: the same
# instances, every other row borrowed from h20-*.json (not run again), previous-hour demand. Seeds come in rounds
# (ROUNDS, default "5 10"), each map in turn; a rerun resumes. These files record no keep, so FAST in them is
# surge:keep=none; to rerun them under today's defaults see "Labels" in
# benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-dates
FAST=surge:base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1
KEEP=$FAST,keep=2
for N in ${ROUNDS:-5 10}; do
  for S in nyc synthetic; do
    surge evaluate --scenario "$S" --data ../shared/data --dates 2022-10-20 2022-12-08 --hours 17 19 --seeds "$N" --taxis 100 \
      --minutes 60 --forecast previous-hour --policies greedy rebalance match "$FAST" "$KEEP" \
      --jobs "${JOBS:-2}" --json "$OUT/keep-$S.json" --resume --borrow "$OUT/h20-$S.json" > "$OUT/summary-keep-$S.txt.tmp"
    mv "$OUT/summary-keep-$S.txt.tmp" "$OUT/summary-keep-$S.txt"
  done
done
