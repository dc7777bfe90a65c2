"""Instantaneous assignment: broadcast-of-local-eligibility matching of free taxis to requests.

Each round every outstanding request broadcasts, the closest free taxi is
eligible, and the globally closest (taxi, request) pair is committed; both
leave the market and the next round begins.  Ties go to the lower taxi index,
then to the older request.
"""

from __future__ import annotations

import numpy as np

from agents.base import Policy, busy_next_hops, head_for, register
from city.graph import City
from city.sim import Observation


def ble_match(dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Iterated closest-pair matching on a (taxis × requests) distance matrix.

    Returns matched taxi rows and request columns, in the order they were committed.
    """
    d = dist.astype(np.float64, copy=True)
    n = min(d.shape)
    rows = np.empty(n, dtype=np.int64)
    cols = np.empty(n, dtype=np.int64)
    for k in range(n):
        flat = int(np.argmin(d))
        i, j = divmod(flat, d.shape[1])
        rows[k], cols[k] = i, j
        d[i, :] = np.inf
        d[:, j] = np.inf
    return rows, cols


def ia_controls(city: City, obs: Observation) -> np.ndarray:
    controls = busy_next_hops(city, obs)
    free = np.flatnonzero(obs.tau == 0)
    if free.size == 0 or obs.req_pickup.size == 0:
        return controls
    d = city.dist[obs.pos[free][:, None], obs.req_pickup[None, :]]
    rows, cols = ble_match(d)
    taxis = free[rows]
    controls[taxis] = head_for(city, obs.pos[taxis], obs.req_pickup[cols], np.ones(taxis.size, dtype=bool))
    return controls


@register
class InstantaneousAssignment(Policy):
    name = "ia"

    def act(self, obs: Observation) -> np.ndarray:
        return ia_controls(self.city, obs)
