"""Compiled planner of the clairvoyant oracle: routes with chaining, built by insertion and improved by LNS.

The plan is one route per taxi: the requests it will pick up, in order.  A
route is timed exactly as :mod:`city.sim` runs it.  A taxi free at step
``ready`` at node ``loc`` reaches request ``r``'s pickup after
``dist[loc, pick[r]]`` steps, waits there if ``r`` has not entered yet, and
picks it up at ``p = max(arrival, entry[r])``; it is busy for
``τ = max(1, dist[pick, drop])`` steps and free again at the drop-off at step
``p + τ + 1``.  A request picked up at step ``p < N`` contributes ``p - entry``
to the total cost and one never picked up ``N - entry``, so the total cost is
``Σ (N - entry) - Σ_served (N - p)``: the planner maximises the *value*
``Σ_served (N - p)`` and a route never holds a request it cannot reach before
step ``N``.

Construction is best insertion: repeatedly the (request, taxi, position) of
largest value gain, delays of the route's later requests included, until no
insertion gains.  Improvement is large-neighbourhood search: remove a few
requests (random, or related in space and time to a seed request), reinsert
the removed and every unserved request by best or regret-2 insertion, and
accept by a simulated-annealing test; the best plan seen is returned.

The simulator hands a taxi that picks up at an intersection the *oldest*
request waiting there, which may not be the one its route names.  After
every change the plan is therefore driven step by step under that rule
(:func:`_project`): where a taxi gets an older request than planned, the two
requests swap places between routes, and the routes as driven replace the
plan.  A plan is thus always one the simulator reproduces exactly, and its
value is the simulator's.  The
random numbers come from a splitmix64 stream of ``seed``, so a seed gives one
plan.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_NEG = -(1 << 40)


@njit(cache=True, inline="always")
def _rand(state: np.ndarray) -> float:
    """A uniform draw in [0, 1) from the splitmix64 stream held in ``state[0]``."""
    state[0] = state[0] + _GOLDEN
    z = state[0]
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def _retime(m: int, j: int, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned) -> int:
    """Re-time route ``m`` from position ``j``; drop (unassign) requests it reaches at or after ``N``; return its value."""
    if j == 0:
        loc, ready = start[m], 0
    else:
        q = routes[m, j - 1]
        loc, ready = drop[q], pt[m, j - 1] + svc[q]
    i = j
    while i < rlen[m]:
        q = routes[m, i]
        p = max(ready + dist[loc, pick[q]], entry[q])
        if p >= N:
            for k in range(i, rlen[m]):
                assigned[routes[m, k]] = -1
            rlen[m] = i
            break
        pt[m, i] = p
        ready = p + svc[q]
        loc = drop[q]
        i += 1
    v = 0
    for k in range(rlen[m]):
        v += N - pt[m, k]
    return v


@njit(cache=True)
def _insert_gain(m: int, r: int, j: int, routes, rlen, pt, start, pick, drop, entry, svc, dist, N) -> int:
    """Value gained by inserting request ``r`` at position ``j`` of route ``m`` (``_NEG`` if it cannot be served)."""
    if j == 0:
        loc, ready = start[m], 0
    else:
        q = routes[m, j - 1]
        loc, ready = drop[q], pt[m, j - 1] + svc[q]
    p = max(ready + dist[loc, pick[r]], entry[r])
    if p >= N:
        return _NEG
    gain = N - p
    ready = p + svc[r]
    loc = drop[r]
    for i in range(j, rlen[m]):
        q = routes[m, i]
        p = max(ready + dist[loc, pick[q]], entry[q])
        old = pt[m, i]
        if p == old:
            break
        if p >= N:
            for k in range(i, rlen[m]):
                gain -= N - pt[m, k]
            break
        gain -= p - old
        ready = p + svc[q]
        loc = drop[q]
    return gain


@njit(cache=True)
def _best_in_route(m: int, r: int, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, K):
    best, bj = _NEG, -1
    if rlen[m] >= K:
        return best, bj
    for j in range(rlen[m] + 1):
        g = _insert_gain(m, r, j, routes, rlen, pt, start, pick, drop, entry, svc, dist, N)
        if g > best:
            best, bj = g, j
    return best, bj


@njit(cache=True)
def _do_insert(m, r, j, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned, val) -> None:
    for k in range(rlen[m], j, -1):
        routes[m, k] = routes[m, k - 1]
    routes[m, j] = r
    rlen[m] += 1
    assigned[r] = m
    val[m] = _retime(m, j, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned)


@njit(cache=True)
def _do_remove(r, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned, val) -> None:
    m = assigned[r]
    j = 0
    while routes[m, j] != r:
        j += 1
    for k in range(j, rlen[m] - 1):
        routes[m, k] = routes[m, k + 1]
    rlen[m] -= 1
    assigned[r] = -1
    val[m] = _retime(m, j, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned)


@njit(cache=True)
def _reinsert(pool, regret: bool, noise: float, state, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned, val, K) -> None:
    """Insert the unassigned requests of ``pool`` one at a time, best gain first (or largest regret-2), until none gains.

    ``noise`` scales a random factor on each gain, diversifying the search.
    """
    M = routes.shape[0]
    P = pool.size
    if P == 0:
        return
    gain = np.full((P, M), _NEG, dtype=np.int64)
    pos = np.full((P, M), -1, dtype=np.int64)
    alive = np.ones(P, dtype=np.bool_)
    for a in range(P):
        for m in range(M):
            g, j = _best_in_route(m, pool[a], routes, rlen, pt, start, pick, drop, entry, svc, dist, N, K)
            gain[a, m] = g
            pos[a, m] = j
    while True:
        best_score, ba, bm = -1e300, -1, -1
        for a in range(P):
            if not alive[a]:
                continue
            g1, m1, g2 = _NEG, -1, 0
            for m in range(M):
                g = gain[a, m]
                if g > g1:
                    g2 = max(g1, 0)
                    g1, m1 = g, m
                elif g > g2:
                    g2 = g
            if g1 <= 0:
                continue
            score = float(g1 - g2) if regret else float(g1)
            if noise > 0.0:
                score *= 1.0 + noise * (_rand(state) - 0.5)
            if score > best_score:
                best_score, ba, bm = score, a, m1
        if ba < 0:
            return
        r = pool[ba]
        _do_insert(bm, r, pos[ba, bm], routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned, val)
        alive[ba] = False
        for a in range(P):
            q = pool[a]
            if assigned[q] >= 0:
                alive[a] = False
            elif not alive[a]:
                alive[a] = True  # pushed out of route bm by the insertion: back in the pool
                for m in range(M):
                    g, j = _best_in_route(m, q, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, K)
                    gain[a, m] = g
                    pos[a, m] = j
            if alive[a]:
                g, j = _best_in_route(bm, q, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, K)
                gain[a, bm] = g
                pos[a, bm] = j


@njit(cache=True)
def _project(routes, rlen, pt, start, pick, drop, entry, svc, N, assigned, val, node_ptr, node_req, dist) -> int:
    """Drive the routes under the simulator's oldest-first pickup rule and make the routes as driven the plan.

    Returns the number of swaps (pickups that got another request than planned).  The routes as
    driven may be timed earlier than they were driven (a swapped-in request entered earlier), so
    :func:`_settle` repeats this until no swap is left.
    """
    M, K = routes.shape
    taken = np.zeros(node_ptr.shape[0] - 1, dtype=np.int64)
    head = np.zeros(M, dtype=np.int64)
    ready = np.zeros(M, dtype=np.int64)
    loc = start.astype(np.int64).copy()
    slot = np.full(pick.shape[0], -1, dtype=np.int64)
    for m in range(M):
        for i in range(rlen[m]):
            slot[routes[m, i]] = i
    swaps = 0
    for t in range(N):
        for m in range(M):
            if head[m] >= rlen[m] or ready[m] > t:
                continue
            r = routes[m, head[m]]
            if max(ready[m] + dist[loc[m], pick[r]], entry[r]) != t:
                continue
            v = pick[r]
            got = node_req[node_ptr[v] + taken[v]]
            taken[v] += 1
            if got != r:
                swaps += 1
                other = assigned[got]
                if other >= 0:
                    routes[other, slot[got]] = r
                    slot[r] = slot[got]
                else:
                    slot[r] = -1
                assigned[r] = other
                assigned[got] = m
                routes[m, head[m]] = got
                slot[got] = head[m]
            pt[m, head[m]] = t
            head[m] += 1
            ready[m] = t + svc[got]
            loc[m] = drop[got]
    for m in range(M):
        for i in range(head[m], rlen[m]):
            assigned[routes[m, i]] = -1
        rlen[m] = head[m]
        v = 0
        for i in range(rlen[m]):
            v += N - pt[m, i]
        val[m] = v
    return swaps


@njit(cache=True)
def _settle(routes, rlen, pt, start, pick, drop, entry, svc, N, assigned, val, node_ptr, node_req, dist) -> None:
    """Project until the plan is driven exactly as timed (at most 8 rounds)."""
    for _ in range(8):
        if _project(routes, rlen, pt, start, pick, drop, entry, svc, N, assigned, val, node_ptr, node_req, dist) == 0:
            return
        for m in range(routes.shape[0]):
            val[m] = _retime(m, 0, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned)


@njit(cache=True)
def _pool(removed, nrem, assigned, pick, entry, dist, extra):
    """The requests to reinsert: the removed ones and the ``extra`` unserved ones most related to them."""
    unserved = np.flatnonzero(assigned < 0)
    score = np.full(unserved.size, 1e18)
    for a in range(unserved.size):
        u = unserved[a]
        for b in range(nrem):
            r = removed[b]
            if r == u:
                score[a] = -1.0
                break
            sc = dist[pick[r], pick[u]] + 0.5 * abs(entry[r] - entry[u])
            if sc < score[a]:
                score[a] = sc
    order = np.argsort(score)
    return unserved[order[: min(unserved.size, nrem + extra)]]


@njit(cache=True)
def plan_routes(dist, pick, drop, entry, start, N: int, iters: int, seed: int, node_ptr, node_req, extra: int = 40, K: int = 96):
    """Routes of maximum value found by insertion and ``iters`` LNS iterations.

    Parameters
    ----------
    dist : int16 (n, n) hop counts; pick, drop, entry : int32 (R,) requests; start : int32 (M,) taxi nodes.
    node_ptr, node_req : the requests picked up at each node, oldest first (CSR), from :func:`node_queues`.
    extra : unserved requests, besides the removed ones, offered for reinsertion in an LNS iteration.

    Returns
    -------
    routes : int32 (M, K), rlen : int64 (M,), pt : int64 (M, K) planned pickup steps, value : int64
    """
    M, R = start.shape[0], pick.shape[0]
    svc = np.empty(R, dtype=np.int64)
    for r in range(R):
        svc[r] = max(1, dist[pick[r], drop[r]]) + 1
    routes = np.zeros((M, K), dtype=np.int32)
    rlen = np.zeros(M, dtype=np.int64)
    pt = np.zeros((M, K), dtype=np.int64)
    val = np.zeros(M, dtype=np.int64)
    assigned = np.full(R, -1, dtype=np.int64)
    state = np.array([np.uint64(seed) * _M2 + _GOLDEN], dtype=np.uint64)
    _reinsert(np.flatnonzero(assigned < 0), False, 0.0, state, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned, val, K)
    _settle(routes, rlen, pt, start, pick, drop, entry, svc, N, assigned, val, node_ptr, node_req, dist)
    cur = val.sum()
    b_routes, b_rlen, b_pt, b_val, b_assigned = routes.copy(), rlen.copy(), pt.copy(), val.copy(), assigned.copy()
    best = cur
    temp0 = max(1.0, 0.002 * cur / max(1, R)) * 5.0
    removed = np.empty(R, dtype=np.int64)
    for it in range(iters):
        served = np.flatnonzero(assigned >= 0)
        if served.size == 0:
            break
        s_routes, s_rlen, s_pt, s_val, s_assigned = routes.copy(), rlen.copy(), pt.copy(), val.copy(), assigned.copy()
        q = min(served.size, 3 + int(_rand(state) * min(25, max(1, served.size // 4))))
        kind = _rand(state)
        nrem = 0
        if kind < 0.5:
            seed_r = served[int(_rand(state) * served.size)]
            score = np.empty(served.size)
            for a in range(served.size):
                r = served[a]
                score[a] = (dist[pick[seed_r], pick[r]] + dist[pick[r], pick[seed_r]]
                            + 0.5 * abs(entry[r] - entry[seed_r]) + 4.0 * _rand(state))
            order = np.argsort(score)
            for a in range(q):
                removed[nrem] = served[order[a]]
                nrem += 1
                _do_remove(served[order[a]], routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned, val)
        elif kind < 0.8:
            for _ in range(q):
                live = np.flatnonzero(assigned >= 0)
                if live.size == 0:
                    break
                r = live[int(_rand(state) * live.size)]
                removed[nrem] = r
                nrem += 1
                _do_remove(r, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned, val)
        else:
            m = int(_rand(state) * M)
            while rlen[m] == 0:
                m = int(_rand(state) * M)
            cut = int(_rand(state) * rlen[m])
            tail = routes[m, cut:rlen[m]].copy()
            for r in tail:
                removed[nrem] = r
                nrem += 1
                _do_remove(r, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned, val)
        _reinsert(_pool(removed, nrem, assigned, pick, entry, dist, extra), _rand(state) < 0.5, 0.3 * _rand(state), state, routes, rlen, pt, start, pick, drop, entry, svc, dist, N, assigned, val, K)
        _settle(routes, rlen, pt, start, pick, drop, entry, svc, N, assigned, val, node_ptr, node_req, dist)
        new = val.sum()
        temp = temp0 * (1.0 - it / iters)
        if new >= cur or (temp > 0 and _rand(state) < np.exp((new - cur) / temp)):
            cur = new
            if cur > best:
                best = cur
                b_routes[:], b_rlen[:], b_pt[:], b_val[:], b_assigned[:] = routes, rlen, pt, val, assigned
        else:
            routes[:], rlen[:], pt[:], val[:], assigned[:] = s_routes, s_rlen, s_pt, s_val, s_assigned
    return b_routes, b_rlen, b_pt, best


@njit(cache=True)
def route_value(dist, pick, drop, entry, start, N: int, routes, rlen):
    """Value ``Σ (N - p)`` of given routes, timed exactly; requests reached at or after ``N`` count nothing."""
    total = 0
    for m in range(start.shape[0]):
        loc, ready = start[m], 0
        for i in range(rlen[m]):
            q = routes[m, i]
            p = max(ready + dist[loc, pick[q]], entry[q])
            if p >= N:
                break
            total += N - p
            ready = p + max(1, dist[pick[q], drop[q]]) + 1
            loc = drop[q]
    return total


def node_queues(pick: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Per node, the requests picked up there, oldest (lowest index) first, as CSR arrays."""
    order = np.argsort(pick, kind="stable")
    ptr = np.searchsorted(pick[order], np.arange(n_nodes + 1)).astype(np.int64)
    return ptr, order.astype(np.int64)
