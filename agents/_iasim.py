"""Instantaneous assignment simulated inside a rollout (numba, ``cache=True``): the ``ia`` base policy.

Conventions are those of :mod:`agents._kernels`; the greedy base is in
:mod:`agents._basesim`, and the per-taxi searches both share in :mod:`agents._search`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from agents._search import nearest_request, oldest_at, time_to_pickup


@njit(cache=True, inline="always", _nrt=False)
def _heap_push(heap: np.ndarray, n: int, key: int) -> int:
    """Push ``key`` onto the min-heap ``heap[:n]``; return the new size."""
    j = n
    heap[j] = key
    while j > 0:
        parent = (j - 1) >> 1
        if heap[parent] <= heap[j]:
            break
        heap[parent], heap[j] = heap[j], heap[parent]
        j = parent
    return n + 1


@njit(cache=True, inline="always", _nrt=False)
def _heap_pop(heap: np.ndarray, n: int) -> tuple[int, int]:
    """Pop the smallest key of the min-heap ``heap[:n]``; return it and the new size."""
    top = heap[0]
    n -= 1
    heap[0] = heap[n]
    j = 0
    while True:
        a = 2 * j + 1
        if a >= n:
            break
        if a + 1 < n and heap[a + 1] < heap[a]:
            a += 1
        if heap[j] <= heap[a]:
            break
        heap[j], heap[a] = heap[a], heap[j]
        j = a
    return top, n


@njit(cache=True, _nrt=False)
def simulate_ia(
    horizon: int,
    alive: np.ndarray,
    n_alive: int,
    tpos: np.ndarray,
    tfree: np.ndarray,
    n_arr: int,
    a_pick: np.ndarray,
    a_drop: np.ndarray,
    a_step: np.ndarray,
    e_pick: np.ndarray,
    e_drop: np.ndarray,
    near: np.ndarray,
    near_d: np.ndarray,
    dist: np.ndarray,
    hop_t: np.ndarray,
    act: np.ndarray,
    lb: np.ndarray,
    seen: np.ndarray,
    free: np.ndarray,
    best_d: np.ndarray,
    best_c: np.ndarray,
    target: np.ndarray,
    matched: np.ndarray,
    heap: np.ndarray,
    tail: int = 0,
    place: np.ndarray = np.empty(0, dtype=np.int64),
    home: np.ndarray = np.empty(0, dtype=np.int32),
) -> tuple[int, int]:
    """The instantaneous-assignment base policy for steps ``1 … horizon``; returns ``(Σ g_k + g_H, end)``.

    ``end`` is as in :func:`simulate_greedy`.

    With ``home`` (one entry per taxi, modified) it is the ``rebalance``
    base: a free taxi that the assignment leaves unmatched moves one hop
    toward ``home[i]``, the rebalancing target it had at the decision minute,
    unless it is -1 or reached; a taxi's target is dropped (-1) once it picks
    up, since it came from a state the taxi has left.

    Every step, :func:`agents.ia.ia_controls`: broadcast of local eligibility
    commits the globally closest (distance, taxi, request) pair, retires both,
    and repeats; each taxi's nearest free request is refreshed lazily.  ``lb[i]``
    bounds taxi ``i``'s distance to the alive arrivals among the first
    ``seen[i]`` from below (see :func:`agents._search.nearest_request`): it drops by one when the
    taxi moves a hop and is unknown (-1) after a pickup.
    """
    r0 = e_pick.shape[0]
    mt = tpos.shape[0]
    n_act = 0
    ai = 0
    cost = 0
    homing = home.shape[0] > 0
    for i in range(mt):
        lb[i] = -1
    for k in range(1, horizon + 1):
        while ai < n_arr and a_step[ai] == k:
            act[n_act] = r0 + ai
            n_act += 1
            n_alive += 1
            ai += 1
        nf = 0
        for i in range(mt):
            if tfree[i] <= k:
                free[nf] = i
                target[nf] = -1
                nf += 1
        if nf > 0 and n_alive > 0:
            for f in range(nf):
                i = free[f]
                best_d[f], best_c[f], lb[i] = nearest_request(tpos[i], lb[i], seen[i], ai, alive, act, n_act, near, near_d, e_pick, a_pick, dist)
                seen[i] = ai
            # A binary heap of (distance, taxi) keys; a key whose request was taken
            # meanwhile is refreshed when it surfaces (keys only ever grow).
            n_h = 0
            for f in range(nf):
                if best_c[f] >= 0:
                    n_h = _heap_push(heap, n_h, best_d[f] * mt + f)
            n_m = 0
            while n_h > 0:
                key, n_h = _heap_pop(heap, n_h)
                f = key % mt
                c = best_c[f]
                if not alive[c]:
                    i = free[f]
                    best_d[f], best_c[f], lb[i] = nearest_request(tpos[i], lb[i], seen[i], ai, alive, act, n_act, near, near_d, e_pick, a_pick, dist)
                    if best_c[f] >= 0:
                        n_h = _heap_push(heap, n_h, best_d[f] * mt + f)
                    continue
                target[f] = c
                alive[c] = False
                matched[n_m] = c
                n_m += 1
            for j in range(n_m):
                c = matched[j]
                alive[c] = True
                if c >= r0:
                    # The arrival was hidden while bounds were refreshed: bring them back below it.
                    p = a_pick[c - r0]
                    for f in range(nf):
                        i = free[f]
                        if lb[i] >= 0:
                            lb[i] = min(lb[i], np.int64(dist[tpos[i], p]))
            for f in range(nf):
                c = target[f]
                if c < 0:
                    continue
                i = free[f]
                v = tpos[i]
                p = e_pick[c] if c < r0 else a_pick[c - r0]
                if p != v:
                    tpos[i] = hop_t[p, v]
                    if lb[i] > 0:
                        lb[i] -= 1
                    continue
                r = oldest_at(v, alive, act, n_act, near, near_d, e_pick, a_pick)
                if r < 0:
                    continue
                alive[r] = False
                n_alive -= 1
                drop = e_drop[r] if r < r0 else a_drop[r - r0]
                tpos[i] = drop
                tfree[i] = k + 1 + max(1, np.int64(dist[v, drop]))
                lb[i] = -1
                if homing:
                    home[i] = -1
                if r >= r0:
                    for j in range(n_act):
                        if act[j] == r:
                            act[j] = act[n_act - 1]
                            n_act -= 1
                            break
        if homing:
            for f in range(nf):
                i = free[f]
                h = home[i]
                if target[f] < 0 and h >= 0 and tpos[i] != h:
                    tpos[i] = hop_t[h, tpos[i]]
                    if lb[i] > 0:
                        lb[i] -= 1
        cost += n_alive
    spared = 0
    if tail > 0:
        for i in range(mt):
            a = time_to_pickup(tpos[i], tfree[i] - horizon - 1, tail, alive, act, n_act, near, near_d, e_pick, a_pick, dist)
            spared += (tail - a) * (tail - a)
    elif place.shape[0] > 0:
        for i in range(mt):
            if tfree[i] <= horizon + 1:
                spared += place[tpos[i]]
    return cost + n_alive, spared
