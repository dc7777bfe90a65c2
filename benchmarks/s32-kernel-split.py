"""Where an exact decision's kernel time goes: drawing the samples, the first candidate, the others.

Replays the captured kernel calls of ``--label`` at `surge bench plan`'s state
three ways: every candidate in play (as planned), the first candidate alone,
and none (the samples are still drawn).  The least of ``--rounds`` replays of
each bounds what a saving on the later candidates can give.

    PYTHONPATH=.:benchmarks python benchmarks/s32-kernel-split.py --label surge:adaptive=none,cap=none --data ../shared/data
"""

from __future__ import annotations

import json
import time

import numpy as np

import agents.rollout as R
from bench_state import captured_calls, replay_args


def main() -> None:
    args = replay_args(__doc__, "surge", 5)
    calls = captured_calls(args, args.label)

    def first(active: np.ndarray) -> np.ndarray:
        out = np.zeros_like(active)
        out[0] = True
        return out

    ways = {"every candidate": lambda a: a, "first candidate": first, "none (samples drawn)": np.zeros_like}
    least = {}
    for name, pick in ways.items():
        best = float("inf")
        for _ in range(args.rounds):
            t0 = time.perf_counter()
            for ctx, inp, lo, hi, active, serial in calls:
                R._run(ctx, inp, lo, hi, pick(active), serial)
            best = min(best, time.perf_counter() - t0)
        least[name] = best
    sizes = {"kernel_calls": len(calls), "candidates_mean": float(np.mean([c[4].size for c in calls])),
             "taxis_mean": float(np.mean([c[1].args[4].shape[1] for c in calls])),
             "tracked_requests_mean": float(np.mean([c[1].args[6].size for c in calls]))}
    print(f"{args.label}: {sizes}; least of {args.rounds} replays: " + ", ".join(f"{k} {v:.3f} s" for k, v in least.items()))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"label": args.label, "scenario": args.scenario, "taxis": args.taxis, "steps": args.steps,
                       **sizes, "least_seconds": least}, fh, indent=1)


if __name__ == "__main__":
    main()
