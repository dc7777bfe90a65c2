#!/bin/bash
# One sweep's wall time: --jobs 2 against a local Dask cluster of 2 single-threaded workers (fresh workers each round).
# oracle-auction: the auction oracle (surge evaluate computes the route-planning oracle as its reference anyway).
# Run from the repository root with surge installed with the cluster extra; writes into $OUT.
set -u
OUT=${OUT:-bench-results/cluster}
BIN=${BIN:-.venv/bin}
PORT=${PORT:-8799}
mkdir -p "$OUT"
SWEEP="--hours 17 19 --seeds 4 --taxis 50 --minutes 30 --policies greedy ia oracle-auction"
for round in 1 2; do
  rm -f "$OUT/jobs-$round.json" "$OUT/dask-$round.json"
  s=$(date +%s.%N); "$BIN/surge" evaluate $SWEEP --jobs 2 --json "$OUT/jobs-$round.json" > "$OUT/jobs-$round.out" 2>&1; e=$(date +%s.%N)
  echo "round $round jobs2 $(echo "$e - $s" | bc)" >> "$OUT/times.txt"
  "$BIN/dask" scheduler --port "$PORT" --no-dashboard > "$OUT/sched.log" 2>&1 & SP=$!
  sleep 3
  NUMBA_NUM_THREADS=1 "$BIN/dask" worker "tcp://127.0.0.1:$PORT" --nworkers 2 --nthreads 1 --no-dashboard > "$OUT/workers.log" 2>&1 & WP=$!
  sleep 8
  s=$(date +%s.%N); "$BIN/surge" evaluate $SWEEP --cluster "tcp://127.0.0.1:$PORT" --json "$OUT/dask-$round.json" > "$OUT/dask-$round.out" 2>&1; e=$(date +%s.%N)
  echo "round $round dask2 $(echo "$e - $s" | bc)" >> "$OUT/times.txt"
  kill $WP; sleep 2; kill $SP; wait
done
