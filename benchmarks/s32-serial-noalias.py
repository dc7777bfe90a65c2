"""Is the serial kernel slower because numba marks a parallel region's array arguments ``noalias``?

numba compiles the body of a parallel loop with its ``noalias`` flag set
(``parfors/parfor_lowering.py``), a flag that ``@njit`` does not expose.
This script, given ``--noalias``, sets that flag's default for every function
it compiles (numba internals: ``Flags.options["noalias"]``), in a cache folder
of its own, and then replays the captured calls of ``--label`` on one kernel
thread with the serial kernel and with the parallel one.  If the flag were
the cause, the serial kernel would catch up.

    PYTHONPATH=.:benchmarks python benchmarks/s32-serial-noalias.py --label surge:adaptive=none,cap=none --data ../shared/data [--noalias]
"""

from __future__ import annotations

import os
import sys
import tempfile

NOALIAS = "--noalias" in sys.argv
if NOALIAS:
    sys.argv.remove("--noalias")
os.environ["NUMBA_CACHE_DIR"] = os.path.join(tempfile.gettempdir(), f"surge-s32-noalias-{int(NOALIAS)}")
if NOALIAS:
    from numba.core.compiler import Flags

    Flags.options["noalias"]._default = True

import json  # noqa: E402

import numba  # noqa: E402

import agents._kernels as K  # noqa: E402
from bench_state import captured_calls, replay, replay_args  # noqa: E402


def main() -> None:
    args = replay_args(__doc__, "surge", 5)
    calls = captured_calls(args, args.label, fill_lists=True)

    eight = lambda n: 8  # noqa: E731
    replay(calls, K.rollout_costs_serial, eight)
    numba.set_num_threads(1)
    seconds: dict[str, list[float]] = {"serial": [], "parallel, 1 thread": []}
    for _ in range(args.rounds):
        seconds["serial"].append(replay(calls, K.rollout_costs_serial, eight))
        seconds["parallel, 1 thread"].append(replay(calls, K.rollout_costs, eight))
    least = {k: min(v) for k, v in seconds.items()}
    print(f"{args.label}, noalias {'on' if NOALIAS else 'off'}: least of {args.rounds} replays: "
          + ", ".join(f"{k} {v:.3f} s" for k, v in least.items()))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"label": args.label, "noalias": NOALIAS, "seconds": seconds, "least": least}, fh, indent=1)


if __name__ == "__main__":
    main()
