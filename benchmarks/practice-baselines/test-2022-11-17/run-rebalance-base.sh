#!/bin/sh
# surge rolled out over rebalance (base=rebalance, scope=map) added to the test-date runs of run.sh and
# run-real-level.sh: the same instances and files, previous-hour demand for every policy; a resumed run
# computes only the added label, seed by seed. The two maps run side by side.
# A bare `surge` in these files is the greedy rollout, as they record; to rerun them under today's defaults see
# "Labels" in benchmarks/practice-baselines/test-2022-11-17/README.md.
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
