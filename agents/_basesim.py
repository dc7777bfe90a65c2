"""The greedy base policy simulated inside a rollout (numba, ``cache=True``) and its one-taxi shadow replay.

The per-taxi searches it shares with the ``ia`` simulation (:mod:`agents._iasim`) are in :mod:`agents._search`.

Conventions are those of :mod:`agents._kernels`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from agents._sampling import BIG_HOPS
from agents._search import nearest_request, oldest_at, time_to_pickup, walk


@njit(cache=True, _nrt=False)
def simulate_greedy(
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
    memo_key: np.ndarray,
    memo_d: np.ndarray,
    memo_c: np.ndarray,
    tick: np.ndarray,
    tail: int = 0,
    place: np.ndarray = np.empty(0, dtype=np.int64),
) -> tuple[int, int, int, int]:
    """The greedy base policy for steps ``1 … horizon``, event by event; returns ``(Σ g_k + g_H, T, events, end)``.

    ``end`` values the taxis' state after the horizon: with ``tail > 0``,
    ``Σ_i (tail - a_i)²``, ``a_i`` taxi i's time to its next pickup
    (:func:`agents._search.time_to_pickup`); else with ``place`` (one value per node),
    ``Σ_i place[v_i]`` over the taxis free after the horizon, ``v_i`` taxi i's
    node (a busy taxi's drop-off is the request's, not a choice); else 0.

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

    For the shadow shortcut (:func:`shadow_greedy`), when ``ag >= 0`` the
    deciding agent (taxi ``ag``) has its state recorded at the start of each
    step, ``(node, target)`` in ``rec_pos``/``rec_tgt``, until ``T``, the first
    step at which it stands at its target to pick up (``BIG_HOPS`` if never); when
    ``ev_step`` is not empty every pickup is recorded there as (step, code).

    Taxis that look for their nearest request from the same node in the same
    step get the same answer (nothing is picked up while the step's plans are
    made), and a herd sharing a target soon moves in lockstep: when
    ``memo_key`` is not empty (one entry per node), a node's search is kept
    under the step's ``tick`` (a counter that only grows, ``tick[0]``) and
    reused.
    """
    r0 = e_pick.shape[0]
    mt = tpos.shape[0]
    n_act = 0
    ai = 0
    cost = 0
    t_first = BIG_HOPS
    n_ev = 0
    record_ev = ev_step.shape[0] > 0
    share = memo_key.shape[0] > 0
    for i in range(mt):
        need[i] = tfree[i] > 1
        tgt[i] = plan_c[i] if tfree[i] <= 1 else -1
        kanc[i] = 1
        d0[i] = plan_d[i]
    for k in range(1, horizon + 1):
        tick[0] += 1
        if ag >= 0 and t_first == BIG_HOPS:
            c = tgt[ag]
            v = tpos[ag]
            if c >= 0:
                v = walk(v, e_pick[c] if c < r0 else a_pick[c - r0], min(k - kanc[ag], d0[ag]), hop_t)
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
                    v = walk(v, p, min(k - kanc[i], d0[i]), hop_t)
                if share and memo_key[v] == tick[0]:
                    d = memo_d[v]
                    c2 = memo_c[v]
                else:
                    d, c2, _ = nearest_request(v, -1, 0, 0, alive, act, n_act, near, near_d, e_pick, a_pick, dist)
                    if share:
                        memo_key[v] = tick[0]
                        memo_d[v] = d
                        memo_c[v] = c2
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
                v = walk(tpos[i], pt, k - kanc[i], hop_t)
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
            if i == ag and t_first == BIG_HOPS:
                t_first = k
            c = tgt[i]
            v = e_pick[c] if c < r0 else a_pick[c - r0]
            r = oldest_at(v, alive, act, n_act, near, near_d, e_pick, a_pick)
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
    spared = 0
    if tail > 0 or place.shape[0] > 0:
        for i in range(mt):
            v = tpos[i]
            c = tgt[i]
            if tfree[i] <= horizon + 1 and c >= 0:
                v = walk(v, e_pick[c] if c < r0 else a_pick[c - r0], min(horizon + 1 - kanc[i], d0[i]), hop_t)
            if tail > 0:
                a = time_to_pickup(v, tfree[i] - horizon - 1, tail, alive, act, n_act, near, near_d, e_pick, a_pick, dist)
                spared += (tail - a) * (tail - a)
            elif tfree[i] <= horizon + 1:
                spared += place[v]
    return cost + n_alive, t_first, n_ev, spared


@njit(cache=True, _nrt=False)
def shadow_greedy(
    horizon: int,
    c: int,
    ref: int,
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
    stands at its target (in ``c`` or in the reference candidate ``ref``, an
    earlier one that is not a pickup) every other taxi of ``c`` does exactly
    what it does in ``ref``, whose pickups (``ev_step``/``ev_code``) are
    replayed here.  If neither agent
    reaches a pickup within the horizon the two costs are equal; if at the
    start of a step the agent's (node, target) equals that of a fully
    simulated candidate ``f`` (``full[f]``) that has not picked up yet either,
    the whole states agree and so do the rest of the rollouts.  Otherwise
    -1: ``c`` needs a full simulation.  ``alive`` holds ``ref``'s alive
    flags at step 1 (arrivals included) and is modified.
    """
    r0 = e_pick.shape[0]
    t_ref = rec_t[ref]
    kanc = 1
    need = False
    n_act = 0
    ai = 0
    e = 0
    for k in range(1, horizon + 2):
        if k > t_ref:
            return -1
        if k == horizon + 1:
            return ref
        v = pos
        if tgt >= 0:
            v = walk(v, e_pick[tgt] if tgt < r0 else a_pick[tgt - r0], min(k - kanc, d0), hop_t)
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
            d, c2, _ = nearest_request(v, -1, 0, 0, alive, act, n_act, near, near_d, e_pick, a_pick, dist)
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
                v = walk(pos, e_pick[tgt] if tgt < r0 else a_pick[tgt - r0], k - kanc, hop_t)
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


