#!/bin/sh
# The paper's baseline, garces2023, on the real map's main-table instances at 17 and 19 h (the paper's date, previous-hour
# demand for every policy), for the share of the greedy->oracle gap it closes. The rows of greedy, rebalance, match and
# FAST (surge:keep=none: the file records no keep) are borrowed from fast-nyc.json, so only garces2023 runs. Seeds come
# in rounds (ROUNDS, default "5 10"), so that a run cut short holds whole seeds at both hours. To rerun it under today's
# defaults see "Labels" in benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-2022-11-17
FAST=surge:base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1
for N in ${ROUNDS:-5 10}; do
  surge evaluate --scenario nyc --data ../shared/data --date 2022-11-17 --hours 17 19 --seeds "$N" --taxis 100 \
      --minutes 60 --forecast previous-hour --policies greedy rebalance match "$FAST" garces2023 --jobs "${JOBS:-1}" \
      --json "$OUT/garces-nyc.json" --resume --borrow "$OUT/fast-nyc.json" > "$OUT/summary-garces-nyc.txt.tmp"
  mv "$OUT/summary-garces-nyc.txt.tmp" "$OUT/summary-garces-nyc.txt"
done
