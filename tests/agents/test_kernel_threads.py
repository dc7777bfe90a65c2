"""The rollout kernels on any number of threads: one decision, whether they run on every core, a share of them, or the calling thread."""

from __future__ import annotations

import dataclasses

import numba
import numpy as np

from agents import _kernels as K
from agents.rollout import StepContext, agent_costs, plan_agent
from tests.agents.test_rollout import context, grid_city, random_state, uniform_forecast


def test_decisions_do_not_depend_on_threads() -> None:
    city = grid_city(6, 5)
    obs = random_state(city, np.random.default_rng(4), taxis=8, requests=9)
    ctx = context(city, obs, uniform_forecast(city, [0.4, 1.2, 0.7, 0.1]), horizon=4, samples=64)
    agent = int(np.flatnonzero(obs.tau == 0)[0])
    before = numba.get_num_threads()
    try:
        runs = []
        for threads in sorted({1, before}):
            numba.set_num_threads(threads)
            runs.append(agent_costs(ctx, ctx.base_controls[:agent], agent)[1])
    finally:
        numba.set_num_threads(before)
    for r in runs[1:]:
        np.testing.assert_array_equal(runs[0], r)


def test_a_one_thread_share_runs_a_one_thread_region_where_the_layer_allows() -> None:
    """Once the process runs OpenMP or TBB regions, a share of one runs the parallel kernel on one thread; otherwise the serial kernel."""
    from agents.kernel_threads import serial_now, threadsafe_regions

    before = numba.get_num_threads()  # starts the threading layer
    try:
        threadsafe = numba.threading_layer() in ("omp", "tbb")
        assert threadsafe_regions() == threadsafe
        assert serial_now(False, lambda: 1) == (not threadsafe)
        assert numba.get_num_threads() == (1 if threadsafe else before)
        assert serial_now(True, lambda: 2) and not serial_now(False, lambda: 2)
        assert numba.get_num_threads() == min(2, numba.config.NUMBA_NUM_THREADS)
    finally:
        numba.set_num_threads(before)


def test_the_parallel_kernel_gives_one_result_in_any_number_of_groups_and_lists_rows_as_listed_up_front() -> None:
    """Each group of chunks lists nearest requests lazily in a copy of its own, merged back after the region."""
    from agents.rollout import kernel_args
    from agents.rollout_inputs import decision_inputs

    city = grid_city(7, 6)
    obs = random_state(city, np.random.default_rng(11), taxis=10, requests=9)
    ctx = context(city, obs, uniform_forecast(city, [0.6, 1.4, 0.2, 2.0]), horizon=4, samples=64, seed=3)
    u = ctx.base_controls.copy()
    agent = next(int(a) for a in np.flatnonzero(obs.tau == 0) if decision_inputs(ctx, u[:a], int(a)).cands.size > 1)
    runs = []
    before = numba.get_num_threads()
    try:
        for threads, chunks, groups in ((1, 8, 1), (2, 16, 2), (2, 5, 3), (2, 16, 1), (2, 2, 7)):
            numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
            inp = decision_inputs(ctx, u[:agent], agent)  # its lists fresh, no row listed
            assert (inp.args[9][:, 0] < 0).all()
            out, settled = K.rollout_costs(*kernel_args(ctx, inp, 0, 64, np.ones(inp.cands.size, dtype=bool)), chunks, groups)
            runs.append((out, settled, inp.args[8], inp.args[9], inp.args[6]))
    finally:
        numba.set_num_threads(before)
    for out, settled, near, near_d, e_pick in runs:
        np.testing.assert_array_equal(out, runs[0][0])
        np.testing.assert_array_equal(settled, runs[0][1])
        listed = near_d[:, 0] >= 0
        ref, ref_d = K.nearest_lists(city.dist, e_pick, near.shape[1])
        assert listed.any() and (listed == (runs[0][3][:, 0] >= 0)).all()  # the rows the samples searched from, all kept
        np.testing.assert_array_equal(near[listed], ref[listed])
        np.testing.assert_array_equal(near_d[listed], ref_d[listed])


def test_adaptive_decisions_do_not_depend_on_threads() -> None:
    """Adaptive batches run on the kernel threads, in the calling thread, or as a core share allows: one choice.

    Each way plans the step from a fresh context, so that each lists the
    nearest requests itself (up front, or lazily on one thread).
    """
    from agents.rollout import _plan

    city = grid_city(7, 6)
    obs = random_state(city, np.random.default_rng(6), taxis=10, requests=9)

    def fresh() -> StepContext:
        ctx = context(city, obs, uniform_forecast(city, [0.6, 1.4, 0.2, 2.0]), horizon=4, samples=96, seed=2)
        return dataclasses.replace(ctx, config=dataclasses.replace(ctx.config, adaptive=1.0, batch=8))

    shares = iter([1, 2] * 1000)  # a share that changes from batch to batch
    ways = {
        "kernel threads": lambda ctx, u, a: plan_agent(ctx, u, a),
        "calling thread": lambda ctx, u, a: _plan(ctx, u, a, serial=True),
        "shared": lambda ctx, u, a: plan_agent(ctx, u, a, threads=lambda: next(shares)),
    }
    runs: dict[str, list[int]] = {}
    before = numba.get_num_threads()
    try:
        for name, plan in ways.items():
            ctx = fresh()
            u = ctx.base_controls.copy()
            runs[name] = []
            for agent in np.flatnonzero(obs.tau == 0):
                runs[name].append(plan(ctx, u[:agent], int(agent)))
                u[agent] = runs[name][-1]
    finally:
        numba.set_num_threads(before)
    assert len(runs["kernel threads"]) >= 5
    assert runs["kernel threads"] == runs["calling thread"] == runs["shared"]
