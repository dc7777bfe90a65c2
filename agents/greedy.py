"""Greedy: every free taxi heads for its nearest outstanding request, without coordination."""

from __future__ import annotations

import numpy as np

from agents.base import Policy, busy_next_hops, head_for, register
from city.graph import City
from city.sim import Observation


def greedy_controls(city: City, obs: Observation) -> np.ndarray:
    """Joint greedy control; ties go to the oldest request (observations list oldest first)."""
    controls = busy_next_hops(city, obs)
    free = np.flatnonzero(obs.tau == 0)
    if free.size == 0 or obs.req_pickup.size == 0:
        return controls
    d = city.dist[obs.pos[free][:, None], obs.req_pickup[None, :]]
    target = obs.req_pickup[np.argmin(d, axis=1)]
    controls[free] = head_for(city, obs.pos[free], target, np.ones(free.size, dtype=bool))
    return controls


@register
class Greedy(Policy):
    name = "greedy"

    def act(self, obs: Observation) -> np.ndarray:
        return greedy_controls(self.city, obs)
