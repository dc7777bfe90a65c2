#!/bin/sh
# The fast rollout over rebalance without keep (FAST: base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1,
# chosen on validation data in benchmarks/rollout-variants/) on the main table's instances: the paper's date, 25 seeds
# at each of its four hours, both maps, previous-hour demand for every policy. Its first 10 seeds are borrowed from
# h20-*.json and the baselines' rows from main-*.json, so only FAST's seeds 10-24 run. These files record no keep, so
# FAST in them is surge:keep=none (surge without keep=2; surge itself: run-keep.sh); a bare `surge` in these files is
# the greedy rollout (greedy base, 10 minutes, local sampling, 1,000 samples, cap=24, adaptive=2), borrowed from
# main-*.json, as the files record; to rerun them under today's defaults see "Labels" in README.md beside this script.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-2022-11-17
FAST=surge:base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1
for MAP in synthetic nyc; do
  [ -e "$OUT/fast-$MAP.json" ] || surge evaluate --scenario "$MAP" --data ../shared/data --date 2022-11-17 --hours 15 17 19 21 \
      --seeds 10 --taxis 100 --minutes 60 --forecast previous-hour --policies greedy ia surge match rebalance "$FAST" --jobs 2 \
      --json "$OUT/fast-$MAP.json" --borrow "$OUT/h20-$MAP.json" > /dev/null
done
for N in ${ROUNDS:-15 20 25}; do
  for MAP in synthetic nyc; do
    surge evaluate --scenario "$MAP" --data ../shared/data --date 2022-11-17 --hours 15 17 19 21 --seeds "$N" --taxis 100 \
        --minutes 60 --forecast previous-hour --policies greedy ia surge match rebalance "$FAST" --jobs 2 \
        --json "$OUT/fast-$MAP.json" --resume --borrow "$OUT/main-$MAP.json" > "$OUT/summary-fast-$MAP.txt.tmp"
    mv "$OUT/summary-fast-$MAP.txt.tmp" "$OUT/summary-fast-$MAP.txt"
  done
done
