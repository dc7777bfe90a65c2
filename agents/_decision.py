"""Compiled per-decision structures of a rollout (numba, ``cache=True``): nearest-request lists, reach, the decision minute.

Computed once per decision, before its samples run (:func:`agents._kernels.rollout_costs`); conventions are those of
:mod:`agents._kernels`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from agents._search import fill_row
from agents._sampling import PICKUP


@njit(cache=True)
def nearest_lists(dist: np.ndarray, pickups: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """For every node ``v``, the ``k`` requests nearest to it by ``(dist[v, pickup], index)``.

    Returns the request indices and their distances, shape ``(n, min(k, R))`` each.
    """
    near, near_d = unfilled_lists(dist.shape[0], pickups.shape[0], k)
    fill_lists(near, near_d, pickups, dist)
    return near, near_d


@njit(cache=True)
def unfilled_lists(n: int, r0: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nearest_lists` with no row listed yet (distance -1): a serial rollout lists the nodes it visits."""
    kk = min(k, r0)
    return np.empty((n, kk), dtype=np.int32), np.full((n, kk), -1, dtype=np.int16)


@njit(cache=True)
def fill_lists(near: np.ndarray, near_d: np.ndarray, pickups: np.ndarray, dist: np.ndarray) -> None:
    """List every row of :func:`unfilled_lists` not listed yet."""
    if near.shape[1] == 0:
        return
    for v in range(near.shape[0]):
        if near_d[v, 0] < 0:
            fill_row(v, near, near_d, pickups, dist)


@njit(cache=True)
def reaches(nodes: np.ndarray, free_from: np.ndarray, spots: np.ndarray, horizon: int, dist: np.ndarray) -> np.ndarray:
    """Whether a taxi free from step ``free_from[i]`` at ``nodes[i]`` can stand on one of ``spots`` by step ``horizon``."""
    out = np.zeros(nodes.shape[0], dtype=np.bool_)
    for i in range(nodes.shape[0]):
        slack = horizon - free_from[i]
        if slack < 0:
            continue
        row = dist[nodes[i]]
        for j in range(spots.shape[0]):
            if row[spots[j]] <= slack:
                out[i] = True
                break
    return out


@njit(cache=True)
def step_zero(
    controls: np.ndarray,
    pos: np.ndarray,
    tau: np.ndarray,
    dest: np.ndarray,
    req_pick: np.ndarray,
    req_drop: np.ndarray,
    dist: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Apply each row of ``controls`` (one joint control per candidate) at the decision minute.

    Returns, per candidate row, the alive flags of the outstanding requests,
    and every taxi's node and first free step afterwards (busy taxis: their
    destination and remaining trip time).
    """
    n_c, m = controls.shape
    r0 = req_pick.shape[0]
    alive = np.ones((n_c, r0), dtype=np.bool_)
    pos1 = np.empty((n_c, m), dtype=np.int32)
    tfree1 = np.empty((n_c, m), dtype=np.int32)
    for c in range(n_c):
        for i in range(m):
            if tau[i] > 0:
                pos1[c, i] = dest[i]
                tfree1[c, i] = tau[i]
                continue
            pos1[c, i] = pos[i] if controls[c, i] == PICKUP else controls[c, i]
            tfree1[c, i] = 1
            if controls[c, i] == PICKUP:
                for r in range(r0):
                    if alive[c, r] and req_pick[r] == pos[i]:
                        alive[c, r] = False
                        pos1[c, i] = req_drop[r]
                        tfree1[c, i] = 1 + max(1, np.int64(dist[pos[i], req_drop[r]]))
                        break
    return alive, pos1, tfree1
