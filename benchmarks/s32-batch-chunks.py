"""Kernel seconds of captured rollout calls replayed with different numbers of sample chunks per parallel region.

The kernel splits each call's samples into chunks, 8 per thread; an adaptive
batch of 50 samples thus runs 16 chunks of about 3 samples on two threads,
each chunk with scratch space of its own.  This replays the calls of
``--label`` at `surge bench plan`'s state with 16, 2 and 4 chunks, and with
one chunk per 25 samples (2 to 16), and prints the least of ``--rounds``
replays of each.  The costs do not depend on the chunks.

    PYTHONPATH=.:benchmarks python benchmarks/s32-batch-chunks.py --label surge:adaptive=2,batch=50,cap=24 --data ../shared/data
"""

from __future__ import annotations

import json

import numba

import agents._kernels as K
from bench_state import captured_calls, replay, replay_args


def main() -> None:
    args = replay_args(__doc__, "surge:adaptive=2,batch=50,cap=24", 7)
    calls = captured_calls(args, args.label)
    T = numba.get_num_threads()
    ways = {"16 (8 per thread)": lambda n: 8 * T, "2": lambda n: T, "4": lambda n: 2 * T,
            "1 per 25 samples": lambda n: max(T, min(8 * T, n // 25))}

    seconds: dict[str, list[float]] = {w: [] for w in ways}
    for _ in range(args.rounds):
        for name, chunks in ways.items():
            seconds[name].append(replay(calls, K.rollout_costs, chunks))
    least = {w: min(s) for w, s in seconds.items()}
    print(f"{args.label}: {len(calls)} kernel calls, least of {args.rounds} replays: "
          + ", ".join(f"{w} chunks {s:.4f} s" for w, s in least.items()))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"label": args.label, "scenario": args.scenario, "taxis": args.taxis, "steps": args.steps,
                       "threads": T, "kernel_calls": len(calls), "seconds": seconds, "least": least}, fh, indent=1)


if __name__ == "__main__":
    main()
