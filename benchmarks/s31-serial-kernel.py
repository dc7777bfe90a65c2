"""Why agents planning side by side could be faster: the serial rollout kernel against the parallel one on one thread.

The policy plans a few minutes at the state of `surge bench plan` while every
call of the rollout kernel is captured (with its nearest-request lists filled,
so that every variant reads the same).  The calls are then replayed, the least
of ``--rounds`` totals kept, four ways:

- ``serial``: :func:`agents._kernels.rollout_costs_serial`, what an agent planning beside another runs;
- ``parallel, 1 thread``: :func:`agents._kernels.rollout_costs` on one kernel thread;
- ``serial, 2 Python threads``: the calls split between two threads, as two agents of ``workers=2`` run them;
- ``parallel nogil, 1 thread each, 2 Python threads``: the same with the parallel kernel, each thread on one
  kernel thread (numba's thread count is per thread).  Session 31 compiled a ``nogil=True`` copy of it here;
  since 16a209b the kernel itself releases the GIL.

    PYTHONPATH=. python benchmarks/s31-serial-kernel.py --scenario synthetic --label garces2023:samples=100
"""

from __future__ import annotations

import json
import threading
import time

import numba
import numpy as np

import agents._kernels as K
from bench_state import captured_calls, replay, replay_args


def main() -> None:
    args = replay_args(__doc__, "garces2023:samples=100", 5)
    calls = captured_calls(args, args.label, fill_lists=True)

    def run(kernel, part, one_thread: bool) -> float:  # noqa: ANN001
        if one_thread:
            numba.set_num_threads(1)
        return replay(part, kernel, lambda n: 8)

    def alone(kernel, one_thread: bool) -> float:  # noqa: ANN001
        return run(kernel, calls, one_thread)

    def side_by_side(kernel, one_thread: bool) -> float:  # noqa: ANN001
        threads = [threading.Thread(target=run, args=(kernel, calls[k::2], one_thread)) for k in (0, 1)]
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
        "parallel nogil, 1 thread each, 2 Python threads": lambda: side_by_side(K.rollout_costs, True),
    }
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
