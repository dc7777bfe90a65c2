#!/bin/sh
# surge against the practical baselines on the paper's test date, the synthetic city, same forecast (previous-hour) for
# every policy (the real map: run-real-level.sh).
# garces2023 is left out: planned exactly at 1,000 samples it took longer than the time this run had on a shared 2-core machine.
# Seeds are added in rounds (3, then 6, then 10) so that a run cut short holds whole seeds.
# A bare `surge` in these files is the greedy rollout, as they record; to rerun them under today's defaults see
# "Labels" in benchmarks/practice-baselines/test-2022-11-17/README.md.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-2022-11-17
for N in 3 6 10; do
  surge evaluate --scenario synthetic --date 2022-11-17 --hours 17 19 --seeds "$N" --taxis 100 --minutes 60 \
    --forecast previous-hour --policies greedy ia surge match rebalance --jobs 1 --json "$OUT/results-synthetic.json" --resume \
    > "$OUT/summary-synthetic.txt.tmp"
  mv "$OUT/summary-synthetic.txt.tmp" "$OUT/summary-synthetic.txt"
done
