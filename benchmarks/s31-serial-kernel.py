"""Why agents planning side by side could be faster: the serial rollout kernel against the parallel one on one thread.

The policy plans a few minutes at the state of `surge bench plan` while every
call of the rollout kernel is captured (with its nearest-request lists filled,
so that every variant reads the same).  The calls are then replayed, the least
of ``--rounds`` totals kept, four ways:

- ``serial``: :func:`agents._kernels.rollout_costs_serial`, what an agent planning beside another runs;
- ``parallel, 1 thread``: :func:`agents._kernels.rollout_costs` on one kernel thread;
- ``serial, 2 Python threads``: the calls split between two threads, as two agents of ``workers=2`` run them;
- ``parallel nogil, 1 thread each, 2 Python threads``: the same with a copy of the parallel kernel compiled
  here with ``nogil=True``, each thread on one kernel thread (numba's thread count is per thread).

    PYTHONPATH=. python benchmarks/s31-serial-kernel.py --scenario synthetic --label garces2023:samples=100
"""

from __future__ import annotations

import json
import threading
import time

import numba
import numpy as np

import agents._kernels as K
import agents.rollout as R
from bench_state import captured_calls, replay_args


def main() -> None:
    args = replay_args(__doc__, "garces2023:samples=100", 5)
    calls = captured_calls(args, args.label, fill_lists=True)
    parallel_nogil = numba.njit(parallel=True, nogil=True)(K.rollout_costs.py_func)

    def replay(kernel, part, one_thread: bool) -> None:  # noqa: ANN001
        if one_thread:
            numba.set_num_threads(1)
        for ctx, inp, lo, hi, active, _ in part:
            cfg = ctx.config
            kernel(R.BASES[cfg.base], cfg.horizon, lo, hi, active, inp.shadow, ctx.shortcuts.share, inp.ag, *inp.args, 8)

    def alone(kernel, one_thread: bool) -> float:  # noqa: ANN001
        t0 = time.perf_counter()
        replay(kernel, calls, one_thread)
        return time.perf_counter() - t0

    def side_by_side(kernel, one_thread: bool) -> float:  # noqa: ANN001
        threads = [threading.Thread(target=replay, args=(kernel, calls[k::2], one_thread)) for k in (0, 1)]
        t0 = time.perf_counter()
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        return time.perf_counter() - t0

    ways = {
        "serial": lambda: alone(K.rollout_costs_serial, False),
        "parallel, 1 thread": lambda: alone(K.rollout_costs, True),
        "serial, 2 Python threads": lambda: side_by_side(K.rollout_costs_serial, False),
        "parallel nogil, 1 thread each, 2 Python threads": lambda: side_by_side(parallel_nogil, True),
    }
    replay(parallel_nogil, calls[:2], True)  # compiles the copy
    before = numba.get_num_threads()
    seconds: dict[str, list[float]] = {w: [] for w in ways}
    try:
        for _ in range(args.rounds):
            for name, way in ways.items():
                seconds[name].append(way())
                numba.set_num_threads(before)
    finally:
        numba.set_num_threads(before)
    out = {"label": args.label, "scenario": args.scenario, "taxis": args.taxis, "hour": args.hour, "steps": args.steps,
           "kernel_calls": len(calls), "rounds": args.rounds, "seconds": seconds,
           "least": {w: min(v) for w, v in seconds.items()}}
    for name, v in seconds.items():
        print(f"{args.label} {name}: least {min(v):.4f} s, median {np.median(v):.4f} s")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
