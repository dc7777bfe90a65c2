"""Compiled inner loops of the one-agent-at-a-time rollout (numba, ``cache=True``).

The rollout of one agent scores each of its candidate controls by Monte-Carlo
simulation of the base policy.  Everything here is a pure function of its
array arguments; random numbers come from a counter-based generator keyed by
``(key, sample, minute, sector)``, so a sample's requests do not depend on the
thread that draws them, on the order samples are drawn in, or on which other
sectors are drawn (pruning skips sectors without changing the rest).

Conventions shared with :mod:`agents.rollout`:

* Requests of a rollout have *codes*: ``0 … R-1`` are the outstanding
  requests it tracks, oldest first; ``R + a`` is the a-th sampled arrival, in
  arrival order.  A smaller code is an older request, so ``(distance, code)``
  ordering reproduces the simulator's oldest-first tie-breaks.
* ``near[v]``/``near_d[v]`` list the tracked requests nearest to node ``v``
  (:func:`nearest_lists`); when all of them are gone a search scans every
  tracked request.
* A taxi is *free from step* ``tfree``: a taxi that picks up at step ``k``
  with trip length ``τ`` is free from step ``k + 1 + τ`` at its drop-off.  Busy
  taxis cannot act, so their intermediate positions are not tracked.
* Step 0 is the decision minute (its joint control is fixed per candidate);
  steps ``1 … H`` run the base policy on sampled arrivals.  The cost of a
  rollout is ``Σ_{k=0..H} g_k + g_H``: the stage costs plus the terminal cost
  (requests still outstanding at the end).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

PICKUP = -1
GREEDY = 0
IA = 1
LIMITED_CE = 0
STANDARD_CE = 1

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0
_BIG = 1 << 30


@njit(cache=True, inline="always")
def _mix(z: np.uint64) -> np.uint64:
    """The splitmix64 finaliser."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True)
def stream_key(seed: int, t: int, agent: int) -> np.uint64:
    """The 64-bit random key of one agent's decision at minute ``t``."""
    z = _mix(np.uint64(seed & 0x7FFFFFFFFFFFFFFF) + _GOLDEN)
    z = _mix(z ^ (np.uint64(t & 0x7FFFFFFFFFFFFFFF) + _GOLDEN))
    return _mix(z ^ (np.uint64(agent & 0x7FFFFFFFFFFFFFFF) + _GOLDEN))


@njit(cache=True, inline="always")
def _stream(key: np.uint64, sample: int, minute: int, sector: int) -> np.uint64:
    z = _mix(key ^ (np.uint64(sample) * _M1 + _GOLDEN))
    z = _mix(z ^ (np.uint64(minute) * _M2 + _GOLDEN))
    return _mix(z ^ (np.uint64(sector) * _M1 + _M2))


@njit(cache=True, inline="always")
def _next(state: np.uint64) -> tuple[np.uint64, float]:
    state = state + _GOLDEN
    return state, float(_mix(state) >> _S11) * _INV53


@njit(cache=True, inline="always")
def _search(cum: np.ndarray, lo: int, hi: int, u: float) -> int:
    """First index ``i`` in ``[lo, hi)`` with ``cum[i] > u · cum[hi-1]`` (inverse CDF)."""
    x = u * cum[hi - 1]
    a, b = lo, hi - 1
    while a < b:
        mid = (a + b) >> 1
        if cum[mid] > x:
            b = mid
        else:
            a = mid + 1
    return a


@njit(cache=True)
def arrival_count(mode: int, rate: float, minute: int, u: float) -> int:
    """Requests entering a sector in one minute under certainty equivalence.

    ``LIMITED_CE`` (surge): ``round(rate)`` when ``rate ≥ 1`` (halves round up),
    else one request with probability ``rate``.  ``STANDARD_CE`` (Garces et
    al.): deterministic mean arrivals, one request each time the rounded
    cumulative mean ``⌊rate · m + ½⌋`` steps up, ``m`` counting minutes from
    the forecast hour's start.
    """
    if mode == LIMITED_CE:
        if rate >= 1.0:
            return int(np.floor(rate + 0.5))
        return 1 if u < rate else 0
    return int(np.floor(rate * (minute + 1) + 0.5) - np.floor(rate * minute + 0.5))


@njit(cache=True)
def sample_arrivals(
    key: np.uint64,
    sample: int,
    horizon: int,
    minute0: int,
    mode: int,
    sectors: np.ndarray,
    eta: np.ndarray,
    pk_ptr: np.ndarray,
    pk_node: np.ndarray,
    pk_cum: np.ndarray,
    dk_ptr: np.ndarray,
    dk_node: np.ndarray,
    dk_cum: np.ndarray,
    beta_cum: np.ndarray,
    rel_node: np.ndarray,
    out_pick: np.ndarray,
    out_drop: np.ndarray,
    out_step: np.ndarray,
) -> int:
    """Draw one sample's future requests for steps ``1 … horizon``; return how many were kept.

    For each step ``k`` and each sector ``q`` of ``sectors`` (ascending), the
    stream ``(key, sample, k, q)`` gives first the count draw, then three
    uniforms per request: pickup node (inverse CDF of ``pk_*`` in ``q``),
    drop-off sector (row ``q`` of ``beta_cum``) and drop-off node (``dk_*``).
    Requests whose pickup is not in ``rel_node`` are drawn but not kept.
    ``minute0`` is the decision step's minute since the forecast hour began.
    """
    n = 0
    for k in range(1, horizon + 1):
        for qi in range(sectors.shape[0]):
            q = sectors[qi]
            st = _stream(key, sample, k, q)
            st, u = _next(st)
            cnt = arrival_count(mode, eta[q], minute0 + k, u)
            for _ in range(cnt):
                st, u1 = _next(st)
                st, u2 = _next(st)
                st, u3 = _next(st)
                p = pk_node[_search(pk_cum, pk_ptr[q], pk_ptr[q + 1], u1)]
                if not rel_node[p]:
                    continue
                q2 = _search(beta_cum[q], 0, beta_cum.shape[1], u2)
                out_pick[n] = p
                out_drop[n] = dk_node[_search(dk_cum, dk_ptr[q2], dk_ptr[q2 + 1], u3)]
                out_step[n] = k
                n += 1
    return n


@njit(cache=True)
def nearest_lists(dist: np.ndarray, pickups: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """For every node ``v``, the ``k`` requests nearest to it by ``(dist[v, pickup], index)``.

    Returns the request indices and their distances, shape ``(n, min(k, R))`` each.
    """
    n = dist.shape[0]
    r0 = pickups.shape[0]
    kk = min(k, r0)
    idx = np.empty((n, kk), dtype=np.int32)
    dd = np.empty((n, kk), dtype=np.int16)
    keys = np.empty(kk, dtype=np.int64)
    for v in range(n):
        m = 0
        row = dist[v]
        for r in range(r0):
            key = np.int64(row[pickups[r]]) * r0 + r
            if m == kk and key >= keys[kk - 1]:
                continue
            j = m if m < kk else kk - 1
            while j > 0 and keys[j - 1] > key:
                keys[j] = keys[j - 1]
                j -= 1
            keys[j] = key
            if m < kk:
                m += 1
        for j in range(kk):
            idx[v, j] = keys[j] % r0
            dd[v, j] = keys[j] // r0
    return idx, dd


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


@njit(cache=True)
def _nearest(
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
    dist_t: np.ndarray,
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
    best_d = _BIG
    best_c = -1
    kl = near.shape[1]
    for j in range(kl):
        r = near[v, j]
        if alive[r]:
            best_d = np.int64(near_d[v, j])
            best_c = r
            break
    if best_c < 0 and r0 > kl:
        row = dist[v]
        for r in range(r0):
            if alive[r]:
                d = np.int64(row[e_pick[r]])
                if d < best_d:
                    best_d = d
                    best_c = r
    if lb >= 0:
        for a in range(seen, n_seen):
            if alive[r0 + a]:
                lb = min(lb, np.int64(dist_t[a_pick[a], v]))
        if lb >= best_d:
            return best_d, best_c, lb
    arr_d = _BIG
    for j in range(n_act):
        c = act[j]
        if alive[c]:
            d = np.int64(dist_t[a_pick[c - r0], v])
            arr_d = min(arr_d, d)
            if d < best_d or (d == best_d and c < best_c):
                best_d = d
                best_c = c
    return best_d, best_c, arr_d


@njit(cache=True)
def _oldest_at(
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
    j = 0
    while j < kl and near_d[v, j] == 0:
        if alive[near[v, j]]:
            return near[v, j]
        j += 1
    if j == kl and r0 > kl:
        for r in range(r0):
            if alive[r] and e_pick[r] == v:
                return r
    best = -1
    for j in range(n_act):
        c = act[j]
        if alive[c] and a_pick[c - r0] == v and (best < 0 or c < best):
            best = c
    return best


@njit(cache=True)
def _walk(v: int, target: int, hops: int, hop_t: np.ndarray) -> int:
    """The node ``hops`` hops from ``v`` along the shortest path to ``target`` (``hop_t[target, v]`` is v's next hop)."""
    for _ in range(hops):
        v = hop_t[target, v]
    return v


@njit(cache=True)
def _simulate_greedy(
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
    dist_t: np.ndarray,
    hop_t: np.ndarray,
    act: np.ndarray,
    tgt: np.ndarray,
    kanc: np.ndarray,
    d0: np.ndarray,
    need: np.ndarray,
    elig: np.ndarray,
    plan_c: np.ndarray,
    plan_d: np.ndarray,
    ag: int,
    rec_pos: np.ndarray,
    rec_tgt: np.ndarray,
    ev_step: np.ndarray,
    ev_code: np.ndarray,
) -> tuple[int, int, int]:
    """The greedy base policy for steps ``1 … horizon``, event by event; returns ``(Σ g_k + g_H, T, events)``.

    A free taxi heading for its nearest request keeps it as the nearest while
    it moves (the target gets exactly one hop closer, every other request at
    most one, and an equally near request that was younger stays younger), so
    the target changes only when it is picked up by another taxi or a strictly
    nearer request arrives.  A taxi's plan is therefore stored as (anchor
    node, anchor step, target, distance) and its position is walked only when
    an event needs it: this is exactly :func:`agents.greedy.greedy_controls`
    applied step by step, at a cost per event instead of per taxi and step.
    ``tpos`` holds each taxi's node at its anchor (or drop-off when busy).
    ``plan_c``/``plan_d`` are the step-1 plans of the taxis free at step 1
    among the outstanding requests (the same in every sample; see
    :func:`_first_plans`), so that only the arrivals are compared here.

    For the shadow shortcut (:func:`_shadow_greedy`), when ``ag >= 0`` the
    deciding agent (taxi ``ag``) has its state recorded at the start of each
    step, ``(node, target)`` in ``rec_pos``/``rec_tgt``, until ``T``, the first
    step at which it stands at its target to pick up (``_BIG`` if never); when
    ``ev_step`` is not empty every pickup is recorded there as (step, code).
    """
    r0 = e_pick.shape[0]
    mt = tpos.shape[0]
    n_act = 0
    ai = 0
    cost = 0
    t_first = _BIG
    n_ev = 0
    record_ev = ev_step.shape[0] > 0
    for i in range(mt):
        need[i] = tfree[i] > 1
        tgt[i] = plan_c[i] if tfree[i] <= 1 else -1
        kanc[i] = 1
        d0[i] = plan_d[i]
    for k in range(1, horizon + 1):
        if ag >= 0 and t_first == _BIG:
            c = tgt[ag]
            v = tpos[ag]
            if c >= 0:
                v = _walk(v, e_pick[c] if c < r0 else a_pick[c - r0], min(k - kanc[ag], d0[ag]), hop_t)
            rec_pos[k] = v
            rec_tgt[k] = c
        first_new = ai
        while ai < n_arr and a_step[ai] == k:
            act[n_act] = r0 + ai
            n_act += 1
            n_alive += 1
            ai += 1
        # Plans for this step, from the state at its start.
        n_el = 0
        for i in range(mt):
            if tfree[i] > k:
                continue
            c = tgt[i]
            if c < 0 and not need[i] and ai == first_new:
                continue
            if need[i] or c < 0:
                v = tpos[i]
                if c >= 0:
                    p = e_pick[c] if c < r0 else a_pick[c - r0]
                    v = _walk(v, p, min(k - kanc[i], d0[i]), hop_t)
                d, c2, _ = _nearest(v, -1, 0, 0, alive, act, n_act, near, near_d, e_pick, a_pick, dist, dist_t)
                tpos[i] = v
                kanc[i] = k
                tgt[i] = c2
                d0[i] = d
                need[i] = False
                continue
            if ai > first_new and kanc[i] + d0[i] > k:
                elig[n_el] = i
                n_el += 1
        # Taxis keeping their target meet this step's arrivals, arrival by arrival
        # (each taxi's updates stay in arrival order; one distance row per arrival).
        for a in range(first_new, ai):
            p = a_pick[a]
            row_t = dist_t[p]
            for e in range(n_el):
                i = elig[e]
                if row_t[tpos[i]] >= d0[i]:
                    continue
                rem = kanc[i] + d0[i] - k
                ct = tgt[i]
                pt = e_pick[ct] if ct < r0 else a_pick[ct - r0]
                v = _walk(tpos[i], pt, k - kanc[i], hop_t)
                d = np.int64(row_t[v])
                tpos[i] = v
                d0[i] = rem
                kanc[i] = k
                if d < rem:
                    tgt[i] = r0 + a
                    d0[i] = d
        # Pickups, in agent order, by the taxis standing at their target.
        for i in range(mt):
            if tfree[i] > k or tgt[i] < 0 or kanc[i] + d0[i] != k:
                continue
            if i == ag and t_first == _BIG:
                t_first = k
            c = tgt[i]
            v = e_pick[c] if c < r0 else a_pick[c - r0]
            r = _oldest_at(v, alive, act, n_act, near, near_d, e_pick, a_pick)
            if r < 0:
                continue
            alive[r] = False
            n_alive -= 1
            if record_ev:
                ev_step[n_ev] = k
                ev_code[n_ev] = r
                n_ev += 1
            drop = e_drop[r] if r < r0 else a_drop[r - r0]
            tpos[i] = drop
            tfree[i] = k + 1 + max(1, np.int64(dist[v, drop]))
            tgt[i] = -1
            need[i] = True
            for j in range(mt):
                if tgt[j] == r:
                    need[j] = True
            if r >= r0:
                for j in range(n_act):
                    if act[j] == r:
                        act[j] = act[n_act - 1]
                        n_act -= 1
                        break
        cost += n_alive
    return cost + n_alive, t_first, n_ev


@njit(cache=True)
def _shadow_greedy(
    horizon: int,
    c: int,
    pos: int,
    tgt: int,
    d0: int,
    alive: np.ndarray,
    n_arr: int,
    a_pick: np.ndarray,
    a_step: np.ndarray,
    e_pick: np.ndarray,
    near: np.ndarray,
    near_d: np.ndarray,
    dist: np.ndarray,
    dist_t: np.ndarray,
    hop_t: np.ndarray,
    act: np.ndarray,
    ev_step: np.ndarray,
    ev_code: np.ndarray,
    n_ev: int,
    full: np.ndarray,
    rec_pos: np.ndarray,
    rec_tgt: np.ndarray,
    rec_t: np.ndarray,
) -> int:
    """Candidate ``c``'s rollout replayed for the deciding agent alone; the candidate whose cost it has, or -1.

    Greedy taxis interact only through pickups, so until the agent first
    stands at its target (in ``c`` or in the reference candidate 0) every
    other taxi of ``c`` does exactly what it does in candidate 0, whose
    pickups (``ev_step``/``ev_code``) are replayed here.  If neither agent
    reaches a pickup within the horizon the two costs are equal; if at the
    start of a step the agent's (node, target) equals that of a fully
    simulated candidate ``f`` (``full[f]``) that has not picked up yet either,
    the whole states agree and so do the rest of the rollouts.  Otherwise
    -1: ``c`` needs a full simulation.  ``alive`` holds candidate 0's alive
    flags at step 1 (arrivals included) and is modified.
    """
    r0 = e_pick.shape[0]
    t_ref = rec_t[0]
    kanc = 1
    need = False
    n_act = 0
    ai = 0
    e = 0
    for k in range(1, horizon + 2):
        if k > t_ref:
            return -1
        if k == horizon + 1:
            return 0
        v = pos
        if tgt >= 0:
            v = _walk(v, e_pick[tgt] if tgt < r0 else a_pick[tgt - r0], min(k - kanc, d0), hop_t)
        for f in range(c):
            if full[f] and k <= rec_t[f] and rec_pos[f, k] == v and rec_tgt[f, k] == tgt:
                return f
        first_new = ai
        while ai < n_arr and a_step[ai] == k:
            act[n_act] = r0 + ai
            n_act += 1
            ai += 1
        if tgt < 0 and not need and ai == first_new:
            pass
        elif need or tgt < 0:
            d, c2, _ = _nearest(v, -1, 0, 0, alive, act, n_act, near, near_d, e_pick, a_pick, dist, dist_t)
            pos = v
            kanc = k
            tgt = c2
            d0 = d
            need = False
        elif kanc + d0 > k:
            for a in range(first_new, ai):
                p = a_pick[a]
                if dist[pos, p] >= d0:
                    continue
                rem = kanc + d0 - k
                v = _walk(pos, e_pick[tgt] if tgt < r0 else a_pick[tgt - r0], k - kanc, hop_t)
                d = np.int64(dist[v, p])
                pos = v
                d0 = rem
                kanc = k
                if d < rem:
                    tgt = r0 + a
                    d0 = d
        if tgt >= 0 and kanc + d0 == k:
            return -1
        while e < n_ev and ev_step[e] == k:
            r = ev_code[e]
            alive[r] = False
            if r == tgt:
                need = True
            if r >= r0:
                for j in range(n_act):
                    if act[j] == r:
                        act[j] = act[n_act - 1]
                        n_act -= 1
                        break
            e += 1
    return -1


@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
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


@njit(cache=True)
def _simulate_ia(
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
    dist_t: np.ndarray,
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
) -> int:
    """The instantaneous-assignment base policy for steps ``1 … horizon``; returns ``Σ g_k + g_H``.

    Every step, :func:`agents.ia.ia_controls`: broadcast of local eligibility
    commits the globally closest (distance, taxi, request) pair, retires both,
    and repeats; each taxi's nearest free request is refreshed lazily.  ``lb[i]``
    bounds taxi ``i``'s distance to the alive arrivals among the first
    ``seen[i]`` from below (see :func:`_nearest`): it drops by one when the
    taxi moves a hop and is unknown (-1) after a pickup.
    """
    r0 = e_pick.shape[0]
    mt = tpos.shape[0]
    n_act = 0
    ai = 0
    cost = 0
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
                best_d[f], best_c[f], lb[i] = _nearest(tpos[i], lb[i], seen[i], ai, alive, act, n_act, near, near_d, e_pick, a_pick, dist, dist_t)
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
                    best_d[f], best_c[f], lb[i] = _nearest(tpos[i], lb[i], seen[i], ai, alive, act, n_act, near, near_d, e_pick, a_pick, dist, dist_t)
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
                r = _oldest_at(v, alive, act, n_act, near, near_d, e_pick, a_pick)
                if r < 0:
                    continue
                alive[r] = False
                n_alive -= 1
                drop = e_drop[r] if r < r0 else a_drop[r - r0]
                tpos[i] = drop
                tfree[i] = k + 1 + max(1, np.int64(dist[v, drop]))
                lb[i] = -1
                if r >= r0:
                    for j in range(n_act):
                        if act[j] == r:
                            act[j] = act[n_act - 1]
                            n_act -= 1
                            break
        cost += n_alive
    return cost + n_alive


@njit(cache=True)
def _first_plans(
    alive0: np.ndarray,
    pos1: np.ndarray,
    tfree1: np.ndarray,
    e_pick: np.ndarray,
    near: np.ndarray,
    near_d: np.ndarray,
    dist: np.ndarray,
    dist_t: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per candidate, each taxi free at step 1: its nearest outstanding request and distance."""
    n_c, mt = pos1.shape
    plan_c = np.full((n_c, mt), -1, dtype=np.int64)
    plan_d = np.full((n_c, mt), _BIG, dtype=np.int64)
    no_act = np.empty(0, dtype=np.int32)
    for c in range(n_c):
        for i in range(mt):
            if tfree1[c, i] <= 1:
                plan_d[c, i], plan_c[c, i], _ = _nearest(pos1[c, i], -1, 0, 0, alive0[c], no_act, 0, near, near_d, e_pick, no_act, dist, dist_t)
    return plan_c, plan_d


@njit(cache=True)
def _run_samples(
    lo: int,
    hi: int,
    s_lo: int,
    out: np.ndarray,
    settled: np.ndarray,
    active: np.ndarray,
    shadow: np.ndarray,
    ag: int,
    plan_c: np.ndarray,
    plan_d: np.ndarray,
    base: int,
    horizon: int,
    key: np.uint64,
    minute0: int,
    mode: int,
    alive0: np.ndarray,
    pos1: np.ndarray,
    tfree1: np.ndarray,
    e_pick: np.ndarray,
    e_drop: np.ndarray,
    near: np.ndarray,
    near_d: np.ndarray,
    rel_node: np.ndarray,
    sectors: np.ndarray,
    eta: np.ndarray,
    pk_ptr: np.ndarray,
    pk_node: np.ndarray,
    pk_cum: np.ndarray,
    dk_ptr: np.ndarray,
    dk_node: np.ndarray,
    dk_cum: np.ndarray,
    beta_cum: np.ndarray,
    max_arrivals: int,
    dist: np.ndarray,
    dist_t: np.ndarray,
    hop_t: np.ndarray,
) -> None:
    """Fill ``out[:, lo-s_lo:hi-s_lo]``: samples ``lo … hi-1`` of :func:`rollout_costs`, with scratch space of their own."""
    n_c = alive0.shape[0]
    r0 = e_pick.shape[0]
    mt = pos1.shape[1]
    cap = max(max_arrivals, 1)
    a_pick = np.empty(cap, dtype=np.int32)
    a_drop = np.empty(cap, dtype=np.int32)
    a_step = np.empty(cap, dtype=np.int32)
    alive = np.empty(r0 + cap, dtype=np.bool_)
    act = np.empty(cap, dtype=np.int32)
    tpos = np.empty(mt, dtype=np.int32)
    tfree = np.empty(mt, dtype=np.int32)
    lb = np.empty(mt, dtype=np.int64)
    seen = np.zeros(mt, dtype=np.int64)
    free = np.empty(mt, dtype=np.int32)
    best_d = np.empty(mt, dtype=np.int64)
    best_c = np.empty(mt, dtype=np.int64)
    target = np.empty(mt, dtype=np.int64)
    matched = np.empty(mt, dtype=np.int64)
    need = np.empty(mt, dtype=np.bool_)
    heap = np.empty(mt + 1, dtype=np.int64)
    use_shadow = base == GREEDY and ag >= 0 and shadow[0]
    n_ev_cap = r0 + cap if use_shadow else 0
    ev_step = np.empty(n_ev_cap, dtype=np.int32)
    ev_code = np.empty(n_ev_cap, dtype=np.int64)
    no_ev = np.empty(0, dtype=np.int32)
    no_code = np.empty(0, dtype=np.int64)
    rec_pos = np.empty((n_c, horizon + 2), dtype=np.int64)
    rec_tgt = np.empty((n_c, horizon + 2), dtype=np.int64)
    rec_t = np.full(n_c, _BIG, dtype=np.int64)
    full = np.zeros(n_c, dtype=np.bool_)
    for s in range(lo, hi):
        n_arr = sample_arrivals(
            key, s, horizon, minute0, mode, sectors, eta, pk_ptr, pk_node, pk_cum,
            dk_ptr, dk_node, dk_cum, beta_cum, rel_node, a_pick, a_drop, a_step,
        )
        col = s - s_lo
        n_ev = 0
        for c in range(n_c):
            full[c] = False
            settled[c, col] = False
            if not active[c] and not (use_shadow and c == 0):
                out[c, col] = 0
                continue
            if use_shadow and c > 0 and shadow[c]:
                alive[:r0] = alive0[0]
                alive[r0 : r0 + n_arr] = True
                f = _shadow_greedy(
                    horizon, c, pos1[c, ag], plan_c[c, ag], plan_d[c, ag], alive, n_arr, a_pick, a_step,
                    e_pick, near, near_d, dist, dist_t, hop_t, act, ev_step, ev_code, n_ev, full, rec_pos, rec_tgt, rec_t,
                )
                if f >= 0:
                    out[c, col] = out[f, col]
                    settled[c, col] = True
                    continue
            g0 = 0
            for r in range(r0):
                alive[r] = alive0[c, r]
                g0 += alive0[c, r]
            alive[r0 : r0 + n_arr] = True
            tpos[:] = pos1[c]
            tfree[:] = tfree1[c]
            if base == GREEDY:
                rec = use_shadow and shadow[c]
                cost, t_first, nev = _simulate_greedy(
                    horizon, alive, g0, tpos, tfree, n_arr, a_pick, a_drop, a_step,
                    e_pick, e_drop, near, near_d, dist, dist_t, hop_t, act, target, seen, best_d, need, free,
                    plan_c[c], plan_d[c], ag if rec else -1, rec_pos[c], rec_tgt[c],
                    ev_step if (rec and c == 0) else no_ev, ev_code if (rec and c == 0) else no_code,
                )
                out[c, col] = g0 + cost
                rec_t[c] = t_first
                full[c] = rec
                if c == 0:
                    n_ev = nev
            else:
                out[c, col] = g0 + _simulate_ia(
                    horizon, alive, g0, tpos, tfree, n_arr, a_pick, a_drop, a_step,
                    e_pick, e_drop, near, near_d, dist, dist_t, hop_t,
                    act, lb, seen, free, best_d, best_c, target, matched, heap,
                )


@njit(cache=True, parallel=True)
def rollout_costs(
    base: int,
    horizon: int,
    s_lo: int,
    s_hi: int,
    active: np.ndarray,
    shadow: np.ndarray,
    ag: int,
    key: np.uint64,
    minute0: int,
    mode: int,
    alive0: np.ndarray,
    pos1: np.ndarray,
    tfree1: np.ndarray,
    e_pick: np.ndarray,
    e_drop: np.ndarray,
    near: np.ndarray,
    near_d: np.ndarray,
    rel_node: np.ndarray,
    sectors: np.ndarray,
    eta: np.ndarray,
    pk_ptr: np.ndarray,
    pk_node: np.ndarray,
    pk_cum: np.ndarray,
    dk_ptr: np.ndarray,
    dk_node: np.ndarray,
    dk_cum: np.ndarray,
    beta_cum: np.ndarray,
    max_arrivals: int,
    dist: np.ndarray,
    dist_t: np.ndarray,
    hop_t: np.ndarray,
    n_chunks: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Rollout cost of every candidate (rows of ``alive0``/``pos1``/``tfree1``) in every sample.

    ``e_pick``/``e_drop`` are the outstanding requests the rollout tracks
    (codes ``0 … R-1``, oldest first) and ``near``/``near_d`` their
    :func:`nearest_lists`.  Each sample's arrivals are drawn once and shared
    by all candidates (common random numbers).  Samples run in parallel in
    ``n_chunks`` contiguous chunks with per-chunk scratch space; the result
    does not depend on the number of threads or chunks.

    Samples ``s_lo … s_hi-1`` are run, for the candidates flagged ``active``
    (the others get 0).  With the greedy base and ``shadow[0]``, candidates
    flagged in ``shadow`` (every candidate but pickup) are first replayed
    for the agent alone (taxi ``ag``, see :func:`_shadow_greedy`); the second
    result flags the (candidate, sample) costs settled that way.
    """
    n_samples = s_hi - s_lo
    out = np.empty((alive0.shape[0], n_samples), dtype=np.int32)
    settled = np.zeros((alive0.shape[0], n_samples), dtype=np.bool_)
    plan_c, plan_d = _first_plans(alive0, pos1, tfree1, e_pick, near, near_d, dist, dist_t)
    n_chunks = max(1, min(n_samples, n_chunks))
    for chunk in prange(n_chunks):
        _run_samples(
            s_lo + chunk * n_samples // n_chunks, s_lo + (chunk + 1) * n_samples // n_chunks, s_lo, out, settled,
            active, shadow, ag, plan_c, plan_d, base, horizon, key, minute0, mode, alive0, pos1, tfree1, e_pick, e_drop, near, near_d, rel_node,
            sectors, eta, pk_ptr, pk_node, pk_cum, dk_ptr, dk_node, dk_cum, beta_cum, max_arrivals, dist, dist_t, hop_t,
        )
    return out, settled


@njit(cache=True, nogil=True)
def rollout_costs_serial(
    base: int,
    horizon: int,
    s_lo: int,
    s_hi: int,
    active: np.ndarray,
    shadow: np.ndarray,
    ag: int,
    key: np.uint64,
    minute0: int,
    mode: int,
    alive0: np.ndarray,
    pos1: np.ndarray,
    tfree1: np.ndarray,
    e_pick: np.ndarray,
    e_drop: np.ndarray,
    near: np.ndarray,
    near_d: np.ndarray,
    rel_node: np.ndarray,
    sectors: np.ndarray,
    eta: np.ndarray,
    pk_ptr: np.ndarray,
    pk_node: np.ndarray,
    pk_cum: np.ndarray,
    dk_ptr: np.ndarray,
    dk_node: np.ndarray,
    dk_cum: np.ndarray,
    beta_cum: np.ndarray,
    max_arrivals: int,
    dist: np.ndarray,
    dist_t: np.ndarray,
    hop_t: np.ndarray,
    n_chunks: int,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`rollout_costs` in the calling thread, without the GIL: for planning several agents at once."""
    n_samples = s_hi - s_lo
    out = np.empty((alive0.shape[0], n_samples), dtype=np.int32)
    settled = np.zeros((alive0.shape[0], n_samples), dtype=np.bool_)
    plan_c, plan_d = _first_plans(alive0, pos1, tfree1, e_pick, near, near_d, dist, dist_t)
    n_chunks = max(1, min(n_samples, n_chunks))
    for chunk in range(n_chunks):
        _run_samples(
            s_lo + chunk * n_samples // n_chunks, s_lo + (chunk + 1) * n_samples // n_chunks, s_lo, out, settled,
            active, shadow, ag, plan_c, plan_d, base, horizon, key, minute0, mode, alive0, pos1, tfree1, e_pick, e_drop, near, near_d, rel_node,
            sectors, eta, pk_ptr, pk_node, pk_cum, dk_ptr, dk_node, dk_cum, beta_cum, max_arrivals, dist, dist_t, hop_t,
        )
    return out, settled
