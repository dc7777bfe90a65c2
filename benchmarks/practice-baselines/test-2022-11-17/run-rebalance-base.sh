#!/bin/sh
# surge rolled out over rebalance (base=rebalance, scope=map) added to the test-date runs of run.sh and
# run-real-level.sh: the same instances and files, previous-hour demand for every policy; a resumed run
# computes only the new label, seed by seed. The two maps run side by side.
# The files record surge's defaults as those of the greedy rollout (greedy base, 10 minutes, local sampling, 1,000
# samples, cap=24, adaptive=2) and read so: a bare `surge` here is the greedy rollout, and a label names what it changes
# from it. Today's `surge` will not resume them (one line names both settings): rerun into an empty folder with
# surge:base=greedy,scope=local,horizon=10,samples=1000,cap=24,adaptive=2 in place of `surge`, and
# ,samples=1000,cap=24,adaptive=2 added to a label with base=rebalance.
set -e
cd "$(dirname "$0")/../../.."
OUT=benchmarks/practice-baselines/test-2022-11-17
NEW=surge:base=rebalance,scope=map
surge evaluate --scenario synthetic --date 2022-11-17 --hours 17 19 --seeds 10 --taxis 100 --minutes 60 \
    --forecast previous-hour --policies greedy ia surge match rebalance "$NEW" --jobs 1 --json "$OUT/results-synthetic.json" --resume \
  > "$OUT/summary-synthetic.txt" &
surge evaluate --scenario nyc --data ../shared/data --date 2022-11-17 --hours 15 17 19 21 --seeds 10 --taxis 100 --minutes 60 \
    --forecast previous-hour --policies greedy ia surge match rebalance "$NEW" --jobs 1 --json "$OUT/results-nyc-real-level.json" --resume \
  > "$OUT/summary-nyc-real-level.txt"
wait
