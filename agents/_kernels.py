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
  tracked request.  A row whose first distance is -1 is not listed yet: a
  search from ``v`` lists it (:func:`unfilled_lists`), so a rollout lists
  only the nodes its taxis visit.  The parallel kernel's threads each list
  into a copy of their own (:func:`rollout_costs`).
* A taxi is *free from step* ``tfree``: a taxi that picks up at step ``k``
  with trip length ``τ`` is free from step ``k + 1 + τ`` at its drop-off.  Busy
  taxis cannot act, so their intermediate positions are not tracked.
* Step 0 is the decision minute (its joint control is fixed per candidate);
  steps ``1 … H`` run the base policy on sampled arrivals.  The cost of a
  rollout is ``Σ_{k=0..H} g_k + g_H``: the stage costs plus the terminal cost
  (requests still outstanding at the end).

The kernels live in five modules: :mod:`agents._sampling` (random numbers
and arrivals), :mod:`agents._basesim` and :mod:`agents._iasim` (the base
policies), :mod:`agents._decision` (the per-decision structures: nearest-request
lists, reach and the decision minute) and this one (the rollout over samples
and candidates).

Nothing in :mod:`agents._sampling`, :mod:`agents._search`, :mod:`agents._basesim`
or :mod:`agents._iasim` allocates, so they are compiled without numba's
reference counting (``_nrt=False``; numba refuses to compile an allocation
there): with it, every call counts each array argument up and down atomically,
on counters the kernel's threads share, for every sample, step and taxi, and
those counts took about a quarter of a rollout's time.
"""

from __future__ import annotations

import os

import numpy as np
from numba import njit, prange

# The parallel kernel opens one OpenMP region per decision.  Idle OpenMP threads
# that spin (GNU's default) take cores from every other agent process on the
# host and from anything else running there; a sleeping one is woken once per
# decision, for microseconds.  Read when numba first starts its threads, after
# this import; a user's own setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from agents._basesim import shadow_greedy, simulate_greedy
from agents._decision import nearest_lists, reaches, step_zero, unfilled_lists
from agents._iasim import simulate_ia
from agents._search import nearest_request
from agents._sampling import (
    BIG_HOPS,
    GREEDY,
    IA,
    LIMITED_CE,
    PICKUP,
    STANDARD_CE,
    arrival_count,
    sample_arrivals,
    stream_key,
)

#: What :mod:`agents.rollout` uses, from here and from the modules above.
__all__ = [
    "GREEDY", "IA", "LIMITED_CE", "PICKUP", "STANDARD_CE", "arrival_count", "nearest_lists", "reaches",
    "rollout_costs", "rollout_costs_serial", "sample_arrivals", "step_zero", "stream_key", "unfilled_lists",
]

@njit(cache=True)
def _first_plans(
    alive0: np.ndarray,
    pos1: np.ndarray,
    tfree1: np.ndarray,
    e_pick: np.ndarray,
    near: np.ndarray,
    near_d: np.ndarray,
    dist: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per candidate, each taxi free at step 1: its nearest outstanding request and distance."""
    n_c, mt = pos1.shape
    plan_c = np.full((n_c, mt), -1, dtype=np.int64)
    plan_d = np.full((n_c, mt), BIG_HOPS, dtype=np.int64)
    no_act = np.empty(0, dtype=np.int32)
    for c in range(n_c):
        for i in range(mt):
            if tfree1[c, i] <= 1:
                plan_d[c, i], plan_c[c, i], _ = nearest_request(pos1[c, i], -1, 0, 0, alive0[c], no_act, 0, near, near_d, e_pick, no_act, dist)
    return plan_c, plan_d


#: Units per request-minute of a rollout's cost with ``place``: the place values are tenths of a hop and
#: ``place`` is in tenths of a request-minute per hop.
PLACE_SCALE = 100


@njit(cache=True)
def _with_tail(path: int, alive: np.ndarray, n: int, spared: int, tail: int, cycle: int) -> int:
    """A rollout's cost with the fluid tail of ``tail`` minutes after the horizon, in units of ``1 / (2 cycle)`` request-minutes.

    Past the horizon the requests still waiting (``g_H``, the alive flags of
    ``alive[:n]``) wait ``tail`` more minutes, less what the taxis serve:
    taxi i, from ``a_i`` minutes on (the time it needs to stand at the
    nearest of them, :func:`agents._search.time_to_pickup`), picks up one
    per ``cycle`` minutes, each sparing the rest of the tail,
    ``Σ_j (tail - a_i - j cycle) ≈ (tail - a_i)² / (2 cycle)``; ``spared`` is
    ``Σ_i (tail - a_i)²`` over the simulated taxis.  Scaled by ``2 cycle`` to
    stay an integer.
    """
    g_end = 0
    for r in range(n):
        g_end += alive[r]
    return 2 * cycle * (path + tail * g_end) - spared


@njit(cache=True)
def _run_samples(
    lo: int,
    hi: int,
    s_lo: int,
    out: np.ndarray,
    settled: np.ndarray,
    active: np.ndarray,
    shadow: np.ndarray,
    share: bool,
    ag: int,
    tail: int,
    cycle: int,
    place_w: int,
    place: np.ndarray,
    home: np.ndarray,
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
    thome = np.empty(home.shape[0], dtype=np.int32)
    use_shadow = base == GREEDY and ag >= 0 and shadow[0]
    # The reference of the shadow replays: the first candidate still in play that can be replayed (a
    # dropped candidate is not simulated to serve as one).
    ref = -1
    if use_shadow:
        for c in range(n_c):
            if active[c] and shadow[c]:
                ref = c
                break
    n_ev_cap = r0 + cap if use_shadow else 0
    ev_step = np.empty(n_ev_cap, dtype=np.int32)
    ev_code = np.empty(n_ev_cap, dtype=np.int64)
    no_ev = np.empty(0, dtype=np.int32)
    no_code = np.empty(0, dtype=np.int64)
    rec_pos = np.empty((n_c, horizon + 2), dtype=np.int64)
    rec_tgt = np.empty((n_c, horizon + 2), dtype=np.int64)
    rec_t = np.full(n_c, BIG_HOPS, dtype=np.int64)
    full = np.zeros(n_c, dtype=np.bool_)
    n_memo = dist.shape[0] if (share and base == GREEDY) else 0
    memo_key = np.full(n_memo, -1, dtype=np.int64)
    memo_d = np.empty(n_memo, dtype=np.int64)
    memo_c = np.empty(n_memo, dtype=np.int64)
    tick = np.zeros(1, dtype=np.int64)
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
            if not active[c]:
                out[c, col] = 0
                continue
            if ref >= 0 and c > ref and shadow[c]:
                alive[:r0] = alive0[ref]
                alive[r0 : r0 + n_arr] = True
                f = shadow_greedy(
                    horizon, c, ref, pos1[c, ag], plan_c[c, ag], plan_d[c, ag], alive, n_arr, a_pick, a_step,
                    e_pick, near, near_d, dist, hop_t, act, ev_step, ev_code, n_ev, full, rec_pos, rec_tgt, rec_t,
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
                rec_ag = ag if rec else -1
                steps = ev_step if c == ref else no_ev
                codes = ev_code if c == ref else no_code
                cost, t_first, nev, spared = simulate_greedy(
                    horizon, alive, g0, tpos, tfree, n_arr, a_pick, a_drop, a_step,
                    e_pick, e_drop, near, near_d, dist, dist_t, hop_t, act, target, seen, best_d, need, free,
                    plan_c[c], plan_d[c], rec_ag, rec_pos[c], rec_tgt[c], steps, codes, memo_key, memo_d, memo_c, tick,
                    tail, place,
                )
                rec_t[c] = t_first
                full[c] = rec
                if c == ref:
                    n_ev = nev
            else:
                # A target is dropped once its taxi picks up, at the decision minute too.
                for i in range(thome.shape[0]):
                    thome[i] = home[i] if tfree1[c, i] <= 1 else -1
                cost, spared = simulate_ia(
                    horizon, alive, g0, tpos, tfree, n_arr, a_pick, a_drop, a_step,
                    e_pick, e_drop, near, near_d, dist, hop_t,
                    act, lb, seen, free, best_d, best_c, target, matched, heap, tail, place, thome,
                )
            if tail > 0:
                out[c, col] = _with_tail(g0 + cost, alive, r0 + n_arr, spared, tail, cycle)
            elif place.shape[0] > 0:
                out[c, col] = PLACE_SCALE * (g0 + cost) + place_w * spared
            else:
                out[c, col] = g0 + cost


@njit(cache=True, parallel=True, nogil=True)
def rollout_costs(
    base: int,
    horizon: int,
    s_lo: int,
    s_hi: int,
    active: np.ndarray,
    shadow: np.ndarray,
    share: bool,
    ag: int,
    tail: int,
    cycle: int,
    place_w: int,
    place: np.ndarray,
    home: np.ndarray,
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
    groups: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """Rollout cost of every candidate (rows of ``alive0``/``pos1``/``tfree1``) in every sample.

    ``e_pick``/``e_drop`` are the outstanding requests the rollout tracks
    (codes ``0 … R-1``, oldest first) and ``near``/``near_d`` their
    :func:`nearest_lists`, each row listed when a taxi first searches from
    it, as the serial kernel does: a decision's taxis search from a few
    percent of the nodes.  Each sample's arrivals are drawn once and shared
    by all candidates (common random numbers).  Samples run in ``n_chunks``
    contiguous chunks with per-chunk scratch space, split into ``groups``
    run side by side (one per kernel thread); each group lists rows in a
    copy of the lists of its own, so no thread reads a row another is
    listing, and the rows listed are kept in ``near``/``near_d`` afterwards.
    The result does not depend on the number of threads, groups or chunks.

    Samples ``s_lo … s_hi-1`` are run, for the candidates flagged ``active``
    (the others get 0).  With the greedy base and ``shadow[0]``, candidates
    flagged in ``shadow`` (every candidate but pickup) are first replayed
    for the agent alone (taxi ``ag``, see :func:`shadow_greedy`); the second
    result flags the (candidate, sample) costs settled that way.  With the
    greedy base and ``share``, taxis searching from the same node in the same
    step share one search (:func:`simulate_greedy`).  It releases the GIL:
    agents planning side by side in threads each run a region of their own
    (:func:`agents.kernel_threads.serial_now`).
    """
    n_samples = s_hi - s_lo
    out = np.empty((alive0.shape[0], n_samples), dtype=np.int32)
    settled = np.zeros((alive0.shape[0], n_samples), dtype=np.bool_)
    plan_c, plan_d = _first_plans(alive0, pos1, tfree1, e_pick, near, near_d, dist)
    n_chunks = max(1, min(n_samples, n_chunks))
    n_groups = max(1, min(n_chunks, groups))
    copies = n_groups if n_groups > 1 else 0  # one group lists in the lists themselves
    g_near = np.empty((copies,) + near.shape, dtype=near.dtype)
    g_near_d = np.empty((copies,) + near_d.shape, dtype=near_d.dtype)
    for g in prange(n_groups):
        if copies:
            g_near[g] = near
            g_near_d[g] = near_d
            lists, lists_d = g_near[g], g_near_d[g]
        else:
            lists, lists_d = near, near_d
        for chunk in range(g * n_chunks // n_groups, (g + 1) * n_chunks // n_groups):
            _run_samples(
                s_lo + chunk * n_samples // n_chunks, s_lo + (chunk + 1) * n_samples // n_chunks, s_lo, out, settled,
                active, shadow, share, ag, tail, cycle, place_w, place, home, plan_c, plan_d, base, horizon, key, minute0, mode, alive0, pos1, tfree1, e_pick, e_drop,
                lists, lists_d, rel_node, sectors, eta, pk_ptr, pk_node, pk_cum, dk_ptr, dk_node, dk_cum, beta_cum, max_arrivals,
                dist, dist_t, hop_t,
            )
    if near.shape[1] > 0:
        for g in range(copies):
            for v in range(near.shape[0]):
                if near_d[v, 0] < 0 and g_near_d[g, v, 0] >= 0:
                    near[v] = g_near[g, v]
                    near_d[v] = g_near_d[g, v]
    return out, settled


@njit(cache=True, nogil=True)
def rollout_costs_serial(
    base: int,
    horizon: int,
    s_lo: int,
    s_hi: int,
    active: np.ndarray,
    shadow: np.ndarray,
    share: bool,
    ag: int,
    tail: int,
    cycle: int,
    place_w: int,
    place: np.ndarray,
    home: np.ndarray,
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
    plan_c, plan_d = _first_plans(alive0, pos1, tfree1, e_pick, near, near_d, dist)
    n_chunks = max(1, min(n_samples, n_chunks))
    for chunk in range(n_chunks):
        _run_samples(
            s_lo + chunk * n_samples // n_chunks, s_lo + (chunk + 1) * n_samples // n_chunks, s_lo, out, settled,
            active, shadow, share, ag, tail, cycle, place_w, place, home, plan_c, plan_d, base, horizon, key, minute0, mode, alive0, pos1, tfree1, e_pick, e_drop, near, near_d, rel_node,
            sectors, eta, pk_ptr, pk_node, pk_cum, dk_ptr, dk_node, dk_cum, beta_cum, max_arrivals, dist, dist_t, hop_t,
        )
    return out, settled
