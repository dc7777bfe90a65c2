"""How many threads a rollout kernel runs on: all the cores, a share of them, or the calling thread alone.

Decisions never depend on it (:func:`agents._kernels.rollout_costs`); it decides only how agents that plan side by
side on one host share its cores (:class:`agents.cores.CoreShare`).
"""

from __future__ import annotations

from collections.abc import Callable

import numba


def serial_now(serial: bool, threads: Callable[[], int] | None) -> bool:
    """Whether the next kernel call runs the serial kernel: if ``serial``, or if ``threads`` now allows one (else it runs on as many as allowed).

    A one-thread share runs the parallel kernel on one thread instead where
    :func:`threadsafe_regions` allows it: it computes faster than the serial
    kernel (numba compiles the same loop body better inside a parallel
    region).  Agents side by side, in-process
    (:meth:`agents.rollout_policy.RolloutPolicy._act_waves`) or a fleet's
    processes on one host (:class:`agents.cores.CoreShare`), get it once
    they have run a region; a fleet's agent does when it warms its kernels
    up (:meth:`agents.taxi.TaxiAgent._warm_up`).  Their fork server never
    starts the layer (:mod:`agents.preload`).
    """
    if serial or threads is None:
        return serial
    n = threads()
    if n == 1 and not threadsafe_regions():
        return True
    set_kernel_threads(n)
    return False


def threadsafe_regions() -> bool:
    """Whether this process has started a threading layer that takes parallel regions from several threads at once (OpenMP, TBB; not workqueue)."""
    try:
        return numba.threading_layer() in ("omp", "tbb")
    except ValueError:
        return False


def set_kernel_threads(n: int) -> None:
    """Threads of this thread's rollout kernel, at most the cores numba sees; decisions do not depend on it (:func:`agents._kernels.rollout_costs`).

    Agents that share a host plan side by side, each on fewer threads, rather
    than each spreading over every core at once.
    """
    if n < 1:
        raise ValueError(f"kernel threads must be at least 1, got {n}")
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
