"""One simulated taxi's searches inside a rollout (numba, ``cache=True``): its nearest request, the oldest at a node,
its walk toward a node, and the time to its next pickup; the greedy and ``ia`` simulations share them.

Conventions are those of :mod:`agents._kernels`.  A search from node ``v`` reads ``dist[v]``, one row of a
row-major matrix (:class:`city.graph.City`), whatever the requests it compares.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from agents._sampling import BIG_HOPS


@njit(cache=True, _nrt=False)
def fill_row(v: int, near: np.ndarray, near_d: np.ndarray, e_pick: np.ndarray, dist: np.ndarray) -> None:
    """List at ``near[v]``/``near_d[v]`` the requests nearest to node ``v`` by ``(dist[v, pickup], code)``."""
    r0 = e_pick.shape[0]
    kk = near.shape[1]
    row = dist[v]
    m = 0
    for r in range(r0):
        d = np.int64(row[e_pick[r]])
        if m == kk and d >= near_d[v, kk - 1]:
            continue
        j = m if m < kk else kk - 1
        while j > 0 and near_d[v, j - 1] > d:
            near[v, j] = near[v, j - 1]
            near_d[v, j] = near_d[v, j - 1]
            j -= 1
        near[v, j] = r
        near_d[v, j] = d
        if m < kk:
            m += 1


@njit(cache=True, inline="always", _nrt=False)
def nearest_request(
    v: int,
    lb: int,
    seen: int,
    n_seen: int,
    alive: np.ndarray,
    act: np.ndarray,
    n_act: int,
    near: np.ndarray,
    near_d: np.ndarray,
    e_pick: np.ndarray,
    a_pick: np.ndarray,
    dist: np.ndarray,
) -> tuple[int, int, int]:
    """The alive request nearest to node ``v`` by ``(distance, code)``; ``(BIG, -1)`` if none.

    ``lb`` bounds from below the distance from ``v`` to the alive arrivals
    among the first ``seen`` (negative when unknown); ``n_seen`` arrivals
    have entered.  Arrivals are younger than every outstanding request, so
    when the nearest outstanding request is no farther than the bound the
    arrivals are not scanned.  Returns ``(distance, code, bound)``, the bound
    now covering all ``n_seen`` arrivals (exact when they were scanned).
    """
    r0 = e_pick.shape[0]
    best_d = BIG_HOPS
    best_c = -1
    kl = near.shape[1]
    if kl > 0 and near_d[v, 0] < 0:
        fill_row(v, near, near_d, e_pick, dist)
    for j in range(kl):
        r = near[v, j]
        if alive[r]:
            best_d = np.int64(near_d[v, j])
            best_c = r
            break
    row = dist[v]
    if best_c < 0 and r0 > kl:
        for r in range(r0):
            if alive[r]:
                d = np.int64(row[e_pick[r]])
                if d < best_d:
                    best_d = d
                    best_c = r
    if lb >= 0:
        for a in range(seen, n_seen):
            if alive[r0 + a]:
                lb = min(lb, np.int64(row[a_pick[a]]))
        if lb >= best_d:
            return best_d, best_c, lb
    arr_d = BIG_HOPS
    for j in range(n_act):
        c = act[j]
        if alive[c]:
            d = np.int64(row[a_pick[c - r0]])
            arr_d = min(arr_d, d)
            if d < best_d or (d == best_d and c < best_c):
                best_d = d
                best_c = c
    return best_d, best_c, arr_d


@njit(cache=True, _nrt=False)
def oldest_at(
    v: int,
    alive: np.ndarray,
    act: np.ndarray,
    n_act: int,
    near: np.ndarray,
    near_d: np.ndarray,
    e_pick: np.ndarray,
    a_pick: np.ndarray,
) -> int:
    """Code of the oldest alive request waiting at node ``v``, or -1."""
    r0 = e_pick.shape[0]
    kl = near.shape[1]
    listed = kl > 0 and near_d[v, 0] >= 0
    j = 0
    while listed and j < kl and near_d[v, j] == 0:
        if alive[near[v, j]]:
            return near[v, j]
        j += 1
    if (j == kl and r0 > kl) or not listed:
        for r in range(r0):
            if alive[r] and e_pick[r] == v:
                return r
    best = -1
    for j in range(n_act):
        c = act[j]
        if alive[c] and a_pick[c - r0] == v and (best < 0 or c < best):
            best = c
    return best


@njit(cache=True, _nrt=False)
def walk(v: int, target: int, hops: int, hop_t: np.ndarray) -> int:
    """The node ``hops`` hops from ``v`` along the shortest path to ``target`` (``hop_t[target, v]`` is v's next hop)."""
    for _ in range(hops):
        v = hop_t[target, v]
    return v


@njit(cache=True, _nrt=False)
def time_to_pickup(
    v: int,
    busy: int,
    tail: int,
    alive: np.ndarray,
    act: np.ndarray,
    n_act: int,
    near: np.ndarray,
    near_d: np.ndarray,
    e_pick: np.ndarray,
    a_pick: np.ndarray,
    dist: np.ndarray,
) -> int:
    """Minutes until a taxi at node ``v`` after the horizon, busy ``busy`` more minutes, can stand at the nearest waiting request; at most ``tail``.

    The nearest request is taken among those still waiting at the end of the
    horizon (tracked and sampled arrivals), from ``v`` (the taxi's node, or
    its drop-off when busy); with none, ``tail``.
    """
    d, _, _ = nearest_request(v, -1, 0, 0, alive, act, n_act, near, near_d, e_pick, a_pick, dist)
    return min(tail, max(0, busy) + d)
