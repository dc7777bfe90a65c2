"""Rollout exactness beyond the nearest-request lists, and pruning's effect on costs (not only on choices).

The compiled kernel lists the ``NEAR_K`` requests nearest to each node and
scans every tracked request past them; a taxi with more than ``NEAR_K``
requests around it exercises that path.  Pruning leaves out taxis and
requests beyond a radius: where nothing left out can reach the deciding
agent's part of the map within the horizon, the pruned and unpruned costs of
every candidate differ by one candidate-independent amount per sample (the
waiting of the requests left out), so the cost differences that decide are
identical.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from agents.rollout import agent_costs
from agents.rollout_config import NEAR_K
from city.sim import Observation
from tests.conftest import line_city
from tests.agents.test_rollout import (
    context,
    grid_city,
    random_state,
    reference_costs,
    uniform_forecast,
)


def test_rollout_costs_equal_simulation_with_more_requests_than_the_near_lists() -> None:
    city = grid_city(5, 4)
    fc = uniform_forecast(city, [0.8, 1.5, 0.4, 1.1])
    requests = 3 * NEAR_K
    for seed, (base, ce, scope) in enumerate((("greedy", "limited", "local"), ("ia", "standard", "map"))):
        obs = random_state(city, np.random.default_rng(50 + seed), taxis=4, requests=requests)
        ctx = context(city, obs, fc, horizon=4, samples=8, base=base, ce=ce, scope=scope, seed=seed, prune=None)
        u = ctx.base_controls.copy()
        free = np.flatnonzero(obs.tau == 0)
        assert free.size > 0
        for agent in free:
            within = (city.dist[obs.pos[agent], obs.req_pickup] <= 4).sum()
            assert within > NEAR_K  # more requests nearby than the kernel's near list holds
            cands, costs = agent_costs(ctx, u[:agent], int(agent))
            np.testing.assert_array_equal(costs, reference_costs(ctx, u[:agent], int(agent)))
            u[agent] = cands[int(np.argmin(costs.sum(axis=1)))]


def test_pruning_changes_costs_only_by_a_candidate_independent_amount() -> None:
    # Two clusters 60 hops apart on a line: the deciding agent with a request near it at one end,
    # two taxis and three requests at the other end, far beyond 2 (H + 1) hops and H minutes.
    city = line_city(80, sectors=8)
    H = 3
    obs = Observation(2, np.array([5, 70, 75], np.int32), np.zeros(3, np.int32), np.full(3, -1, np.int32),
                      np.arange(4), np.array([8, 72, 78, 66], np.int32), np.array([1, 60, 79, 64], np.int32),
                      np.array([0, 0, 1, 2], np.int32))
    fc = uniform_forecast(city, np.full(8, 0.3))
    for base, ce, scope in (("greedy", "limited", "local"), ("ia", "standard", "map")):
        full = context(city, obs, fc, horizon=H, samples=40, base=base, ce=ce, scope=scope, seed=3, prune=None)
        pruned = dataclasses.replace(full, config=dataclasses.replace(full.config, prune=2 * (H + 1)))
        cands, c_full = agent_costs(full, np.zeros(0, np.int32), 0)
        cands_p, c_pruned = agent_costs(pruned, np.zeros(0, np.int32), 0)
        np.testing.assert_array_equal(cands, cands_p)
        offset = c_full - c_pruned
        assert (offset > 0).all()  # the far requests wait in the unpruned rollout only
        np.testing.assert_array_equal(offset, np.broadcast_to(offset[0], offset.shape))  # same for every candidate
        np.testing.assert_array_equal(c_full - c_full[0], c_pruned - c_pruned[0])
