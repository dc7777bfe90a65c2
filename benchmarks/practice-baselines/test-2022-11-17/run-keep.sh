#!/bin/sh
# surge (KEEP: FAST with keep=2, an agent keeping the base policy's control unless a candidate beats it by more than 2
# standard errors; keep=2 chosen on validation data in benchmarks/rollout-variants/) on the main table's instances: the
# paper's date, 25 seeds at each of its four hours, both maps, previous-hour demand. Every other row is borrowed from
# fast-<map>.json, so only KEEP runs. Seeds come in rounds (ROUNDS, default "10 25"), each map in turn; a rerun resumes.
# These files record no keep, so FAST in them is surge:keep=none; to rerun them under today's defaults see "Labels" in
# benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-2022-11-17
FAST=surge:base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1
KEEP=$FAST,keep=2
for N in ${ROUNDS:-10 25}; do
  for MAP in nyc synthetic; do
    surge evaluate --scenario "$MAP" --data ../shared/data --date 2022-11-17 --hours 15 17 19 21 --seeds "$N" --taxis 100 \
        --minutes 60 --forecast previous-hour --policies greedy rebalance match "$FAST" "$KEEP" --jobs "${JOBS:-2}" \
        --json "$OUT/keep-$MAP.json" --resume --borrow "$OUT/fast-$MAP.json" > "$OUT/summary-keep-$MAP.txt.tmp"
    mv "$OUT/summary-keep-$MAP.txt.tmp" "$OUT/summary-keep-$MAP.txt"
  done
done
