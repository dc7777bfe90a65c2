#!/bin/sh
# The validation grid of match and rebalance (2022-08-02, a validation date; hours 17 and 19; seeds 0-4; 100 taxis; 60 minutes;
# rebalance with previous-hour demand).
set -e
cd "$(dirname "$0")/../.."
POLICIES="greedy ia match:cost=hops match:cost=sqrt match:cost=wait match:cost=wait,wait_weight=0.5"
for L in 6 12 24; do for V in 20 50 100 200 500 2000; do POLICIES="$POLICIES rebalance:lookahead=$L,value=$V"; done; done
for LV in 3,500 3,2000 3,10000 6,10000 12,10000; do POLICIES="$POLICIES rebalance:lookahead=${LV%,*},value=${LV#*,}"; done
for S in synthetic nyc; do
  surge evaluate --scenario "$S" --data ../shared/data --date 2022-08-02 --hours 17 19 --seeds 5 --taxis 100 --minutes 60 \
    --forecast previous-hour --policies $POLICIES --jobs 1 --json "benchmarks/practice-baselines/grid-$S.json" --resume
done
