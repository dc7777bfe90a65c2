"""Kernel seconds of a policy's rollouts at `surge bench plan`'s state, replayed: a timing that tolerates a noisy machine.

The policy plans a few minutes at the state of `surge bench plan` (2022-11-17,
seed 0, 25 minutes of greedy play) while every call of the rollout kernel is
captured.  The captured calls are then replayed as they were, ``--rounds``
times, and the least and median total are printed: the least is the figure
to compare, as noise on a shared machine only ever adds time.  Python's
preparation of each decision is not in it.

    PYTHONPATH=. python benchmarks/s30-kernel-replay.py --label surge:adaptive=2,batch=50,cap=12 --data ../shared/data
"""

from __future__ import annotations

import json
import time

import numpy as np

import agents.rollout as R
from bench_state import captured_calls, replay_args


def main() -> None:
    args = replay_args(__doc__, "surge:adaptive=2,batch=50,cap=24", 9)
    calls = captured_calls(args, args.label)
    totals = []
    for _ in range(args.rounds):
        t0 = time.perf_counter()
        for call in calls:
            R._run(*call)
        totals.append(time.perf_counter() - t0)
    out = {"label": args.label, "scenario": args.scenario, "taxis": args.taxis, "hour": args.hour, "steps": args.steps,
           "kernel_calls": len(calls), "rounds": args.rounds, "kernel_seconds_min": min(totals),
           "kernel_seconds_median": float(np.median(totals)), "kernel_seconds": totals}
    print(f"{args.label}: {len(calls)} kernel calls over {args.steps} steps, replayed {args.rounds}×: "
          f"least {min(totals):.4f} s, median {np.median(totals):.4f} s")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
