#!/bin/sh
# surge:keep=none with its sample approximation turned off (samples=1000; cap=12 and adaptive=1 kept), the variant that
# recovered most of the approximations' cost per unit of planning time on validation data (benchmarks/rollout-variants/,
# "one at a time"), on the main table's instances: the paper's date, seeds 0-9 at its four hours, both maps, previous-hour
# demand. Every other row is borrowed from fast-<map>.json, so only the variant runs. These files record no keep, so FAST
# and the variant in them plan without it; to rerun them under today's defaults see "Labels" in
# benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-2022-11-17
FAST=surge:base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1
S1000=surge:base=rebalance,scope=map,horizon=20,samples=1000,cap=12,adaptive=1
for MAP in nyc synthetic; do
  surge evaluate --scenario "$MAP" --data ../shared/data --date 2022-11-17 --hours 15 17 19 21 --seeds 10 --taxis 100 \
      --minutes 60 --forecast previous-hour --policies greedy rebalance match "$FAST" "$S1000" --jobs "${JOBS:-1}" \
      --json "$OUT/samples1000-$MAP.json" --resume --borrow "$OUT/fast-$MAP.json" > "$OUT/summary-samples1000-$MAP.txt.tmp"
  mv "$OUT/summary-samples1000-$MAP.txt.tmp" "$OUT/summary-samples1000-$MAP.txt"
done
