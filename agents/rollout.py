"""One-agent-at-a-time rollout (paper §4.1, Eq. 2): one agent's decision, and the minute it shares with the others.

At minute ``t`` the free taxis decide in agent order.  Agent ℓ scores each
control of its control set (stay, pickup when a request waits at its node,
each out-neighbour): agents before it use their committed controls, agents
after it the base policy's control for the current minute, and then the
base policy runs for every taxi for ``H`` more minutes on requests sampled
from the forecast.  The cost of a rollout is the sum of the stage costs (the
requests outstanding after each minute) plus a terminal cost, the requests
still outstanding at the end; with ``tail`` (off by default) a fluid estimate
of the waiting in the minutes after the horizon is added (:func:`agents._kernels._with_tail`),
or with ``place`` the taxis' expected distance to the forecast's next request (:func:`agents.place_values.place_values`).
The agent takes the control of least Monte-Carlo
mean cost; ties go to staying, then to pickup, then to the lowest node id.
Busy taxis have a single control (their next hop) and are not planned.

The two rollout policies that use it, ``surge`` and ``garces2023``, are in
:mod:`agents.rollout_policy`.

Standard certainty equivalence, as implemented here: η is replaced by its
mean, so a sector receives its requests deterministically, one each time the
rounded cumulative mean ``⌊η · m + ½⌋`` steps up (``m`` minutes since the hour
began).  ρ and δ are replaced by a pre-computed pool per sector, drawn once
per forecast from ρ (pickups, about ``60 η`` of them, like an hour of past
requests) and δ (drop-offs, about the hour's expected drop-offs).  Each
sample draws every request's pickup from its sector's pool, its drop-off
sector from β and its drop-off from that sector's pool, independently, so β
and the order in which requests arrive stay stochastic.
``ce=counts`` keeps the deterministic counts and draws the places from ρ, β
and δ themselves, as limited certainty equivalence does: between the three,
the counts and the pools are told apart.

Determinism: an agent's decision is a pure function of the observation, its
predecessors' committed controls, its index, the forecast, the seed and
``t`` (:func:`plan_agent`).  Its random numbers come from a counter-based
generator keyed by ``(seed, t, agent)`` and, inside, by (sample, minute,
sector), so a separate agent process reproduces in-process decisions bit for
bit and the result does not depend on the number of threads.

Speed: a compiled kernel (:mod:`agents._kernels`) runs the samples in
parallel and shares each sample's requests across the candidate controls
(common random numbers).  It does only the work that can change a cost:
busy taxis are events (free again at a known step and node); the greedy
base policy is simulated event by event (a free taxi keeps its nearest
request as it drives towards it, so only pickups and nearer arrivals
re-plan it); the requests nearest to each node are listed once per
decision; and with ``prune`` (a radius in hops, ``2 (H + 1)`` by default)
taxis and requests farther than that from the deciding agent are left out.
Every shortcut but pruning is exact (``tests/agents/test_rollout.py`` compares the
costs with the simulator); pruning is validated there to reproduce the
unpruned decisions on seeded states.  The exact savings of
:class:`Shortcuts` (skip a decision no candidate can change, replay the
non-pickup candidates for the agent alone, leave out taxis that cannot reach
a pickup, transposed distance rows, one nearest-request search per node and
step, nearest-request lists made as taxis need them) are switchable, and
``tests/agents/test_planning_speed.py`` shows each leaves every decision as it was,
with and without the approximations.  Two approximations are settings, off in
a bare :class:`RolloutConfig` and on in the ``surge`` policy's defaults:
``adaptive`` (successive elimination of candidates on paired differences) and
``cap`` (the agent's nearest taxis only; with the greedy base, the nearest of
those that can pick up).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numba
import numpy as np

from agents import _kernels as K
from agents._adaptive import best_candidate, eliminate
from agents.demand_tables import DemandTables
from agents.greedy import greedy_controls
from agents.ia import ia_controls
from agents.place_values import place_values
from agents.rollout_config import BASES, CE_MODES, NEAR_K, RolloutConfig
from agents.shortcuts import MINUTE_NEAR_K, PlanStats, Shortcuts, transposed
from city.errors import ConfigError
from city.forecast import Forecast
from city.graph import City
from city.sim import PICKUP, Observation


@dataclass(frozen=True)
class StepContext:
    """Everything the agents of one minute share; a pure function of the observation and forecast.

    Attributes
    ----------
    city : City
    config : RolloutConfig
    obs : Observation
    base_controls : ndarray (m,)
        The base policy's joint control for this minute (busy taxis: their next hop).
    tables : DemandTables
        The forecast of the minute's hour.
    minute0 : int
        Minutes since the forecast hour began.
    shortcuts : Shortcuts
        Exact savings in use (all by default).
    near, near_d : ndarray or None
        The minute's nearest-request lists over every outstanding request (``shortcuts.minute_lists``).
    stats : PlanStats
        What the minute's decisions cost and what the shortcuts settled.
    arrival_spots : dict
        Per set of sampled sectors, the nodes where an arrival within the
        horizon can be picked up (:func:`_pickup_spots`): agents of one area share it.
    home : ndarray of int32 (m,) or (0,)
        With the ``rebalance`` base, each taxi's rebalancing target of the
        minute (-1: none), which the simulated taxis keep; empty otherwise.
    """

    city: City
    config: RolloutConfig
    obs: Observation
    base_controls: np.ndarray
    tables: DemandTables
    minute0: int
    shortcuts: Shortcuts = field(default_factory=Shortcuts)
    near: np.ndarray | None = None
    near_d: np.ndarray | None = None
    stats: PlanStats = field(default_factory=PlanStats)
    arrival_spots: dict[bytes, np.ndarray] = field(default_factory=dict, repr=False)
    home: np.ndarray = field(default_factory=lambda: _NO_HOME)


_NO_HOME = np.empty(0, dtype=np.int32)


@dataclass(frozen=True)
class HourInputs:
    """What the ``rebalance`` base needs of the hour's forecast: the rates and the sectors' anchors, computed once an hour."""

    eta: np.ndarray
    anchors: np.ndarray

    @classmethod
    def of(cls, city: City, forecast: Forecast) -> HourInputs:
        # Imported here: scipy's assignment solver is for the rebalance base alone, and an agent of another base
        # joins a run without it.
        from agents.rebalance import sector_anchors

        return cls(eta=np.asarray(forecast.eta, dtype=np.float64), anchors=sector_anchors(city, forecast.rho))


def base_controls(city: City, config: RolloutConfig, obs: Observation, hour: HourInputs | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The base policy's joint control for the minute (what agents after the decider play, and a silent agent's fallback) and its targets.

    The targets are the ``rebalance`` base's (:func:`agents.rebalance.rebalance_plan`
    at its default settings, with the forecast of ``hour``), an empty array for
    the other bases.
    """
    if config.base == "rebalance":
        from agents.rebalance import rebalance_plan  # see HourInputs.of

        if hour is None:
            raise ConfigError("rollout: the rebalance base needs the hour's forecast")
        u, home, _ = rebalance_plan(city, obs, hour.eta, hour.anchors)
        return u, home
    base = greedy_controls(city, obs) if config.base == "greedy" else ia_controls(city, obs)
    return base.astype(np.int32), _NO_HOME


def prepare_step(city: City, config: RolloutConfig, obs: Observation, tables: DemandTables, minute0: int,
                 shortcuts: Shortcuts | None = None, base: np.ndarray | None = None, home: np.ndarray | None = None,
                 hour: HourInputs | None = None) -> StepContext:
    """The shared per-minute context: the base policy's joint control and, with the shortcut, the nearest-request lists.

    ``base`` (and with the ``rebalance`` base its ``home`` targets) is that
    joint control when it is already known (an agent gets it with the
    state), so that it is computed once per minute, not per agent; otherwise
    it is computed here, from ``hour`` for the ``rebalance`` base.
    """
    sc = shortcuts or Shortcuts()
    near = near_d = None
    if sc.minute_lists and obs.req_pickup.size:
        near, near_d = K.nearest_lists(city.dist, np.ascontiguousarray(obs.req_pickup, dtype=np.int32), MINUTE_NEAR_K)
    if base is None:
        base, home = base_controls(city, config, obs, hour)
    base = np.asarray(base, dtype=np.int32)
    if config.base == "rebalance":
        if home is None or len(home) != base.size:
            raise ConfigError("rollout: the rebalance base needs every taxi's target with the minute's base controls")
        home = np.ascontiguousarray(home, dtype=np.int32)
    else:
        home = _NO_HOME
    return StepContext(city, config, obs, base, tables, int(minute0), sc, near, near_d, home=home)


def candidate_controls(city: City, obs: Observation, agent: int) -> np.ndarray:
    """Agent's control set in tie-break order: stay, pickup (if a request waits here), out-neighbours ascending."""
    here = int(obs.pos[agent])
    cands = [here]
    if np.any(obs.req_pickup == here):
        cands.append(PICKUP)
    cands.extend(sorted(int(v) for v in city.neighbors(here)))
    return np.asarray(cands, dtype=np.int32)


def relevant_nodes(city: City, config: RolloutConfig, here: int, dist_t: np.ndarray | None = None) -> np.ndarray:
    """Nodes a decision at ``here`` looks at: within the pruning radius in either direction (all without pruning).

    ``dist_t``, ``city.dist`` transposed, when at hand, gives the distances to ``here`` as one row
    (contiguous when it is :func:`transposed`'s copy).
    """
    if config.prune is None:
        return np.ones(city.n_nodes, dtype=bool)
    to_here = city.dist[:, here] if dist_t is None else dist_t[here]
    return (city.dist[here] <= config.prune) | (to_here <= config.prune)


@dataclass
class _Inputs:
    """One decision's kernel inputs (see :func:`agent_costs`)."""

    cands: np.ndarray
    skip: bool
    args: tuple
    ag: int
    shadow: np.ndarray
    place: np.ndarray
    home: np.ndarray


def _decision_inputs(ctx: StepContext, committed: np.ndarray, agent: int) -> _Inputs:
    city, cfg, obs, sc = ctx.city, ctx.config, ctx.obs, ctx.shortcuts
    if obs.tau[agent] > 0:
        raise ValueError(f"agent {agent} is busy; its only control is its next hop")
    committed = np.asarray(committed, dtype=np.int32)
    if committed.shape != (agent,):
        raise ValueError(f"committed: expected {agent} controls, got {committed.shape}")
    H = cfg.horizon
    greedy = cfg.base == "greedy"
    here = int(obs.pos[agent])
    cands = candidate_controls(city, obs, agent)
    controls = np.repeat(ctx.base_controls[None, :], cands.size, axis=0)
    controls[:, :agent] = committed
    controls[:, agent] = cands
    req_pick = np.ascontiguousarray(obs.req_pickup, dtype=np.int32)
    req_drop = np.ascontiguousarray(obs.req_dropoff, dtype=np.int32)
    alive0, pos1, tfree1 = K.step_zero(controls, obs.pos, obs.tau, obs.dest, req_pick, req_drop, city.dist)

    dist_t, hop_t = transposed(city) if sc.rows else (city.dist.T, city.next_hop.T)
    rel_node = relevant_nodes(city, cfg, here, dist_t)
    if cfg.scope == "local":
        sectors = city.local_sectors(int(city.node_sector[here]))
    else:
        sectors = np.arange(city.n_sectors)
    if cfg.prune is not None:
        sectors = sectors[np.bincount(city.node_sector[rel_node], minlength=city.n_sectors)[sectors] > 0]
    tab = ctx.tables
    mode = CE_MODES[cfg.ce]
    keep = (tfree1.min(axis=0) <= H) & rel_node[pos1].any(axis=0)
    keep[agent] = True
    rel_req = rel_node[req_pick]
    skip = False
    taxis = np.flatnonzero(keep)
    useful = np.ones(taxis.size, dtype=bool)
    capped = cfg.cap is not None and taxis.size > cfg.cap
    # With a tail or place values every simulated taxi's end position is part of the cost: none is left out
    # for not reaching a pickup.
    if greedy and not cfg.tail and not cfg.place and (sc.reach or sc.skip or capped):
        # Where a pickup can happen within the horizon: tracked requests and possible arrivals.
        spots = _pickup_spots(ctx, sectors, rel_node, req_pick[rel_req & alive0.any(axis=0)])
        if sc.skip and PICKUP not in cands:
            skip = not K.reaches(cands, np.ones(cands.size, np.int64), spots, H, city.dist).any()
        if (sc.reach or capped) and not skip:
            others = taxis != agent
            useful[others] = K.reaches(pos1[0, taxis[others]], tfree1[0, taxis[others]].astype(np.int64), spots, H, city.dist)
    # The cap ranks only taxis that can pick up (greedy base): the others never change a cost, so
    # ``reach``, which leaves them out, stays exact under the cap.
    chosen = useful.copy()
    if cfg.cap is not None and chosen.sum() > cfg.cap:
        ranked = np.flatnonzero(useful & (taxis != agent))
        order, _ = cap_ranking(city, obs, here, taxis[ranked])
        chosen[ranked[order[cfg.cap - 1:]]] = False
    taxis = taxis[chosen | (~useful & (not sc.reach))]
    ag = int(np.searchsorted(taxis, agent))
    if sc.minute_lists and ctx.near is not None:
        e_pick, e_drop = req_pick, req_drop
        a0 = np.ascontiguousarray(alive0 & rel_req[None, :])
        near, near_d = ctx.near, ctx.near_d
    else:
        tracked = np.flatnonzero(rel_req)
        e_pick, e_drop = req_pick[tracked], req_drop[tracked]
        a0 = np.ascontiguousarray(alive0[:, tracked])
        if sc.lazy_lists:
            near, near_d = K.unfilled_lists(city.n_nodes, e_pick.size, NEAR_K)
        else:
            near, near_d = K.nearest_lists(city.dist, e_pick, NEAR_K)
    args = (
        np.uint64(K.stream_key(cfg.seed, int(obs.t), agent)), ctx.minute0, mode,
        a0, np.ascontiguousarray(pos1[:, taxis]), np.ascontiguousarray(tfree1[:, taxis]),
        e_pick, e_drop, near, near_d, rel_node,
        sectors.astype(np.int64), tab.eta, tab.pk_ptr, tab.pk_node, tab.pk_cum, tab.dk_ptr, tab.dk_node, tab.dk_cum,
        tab.beta_cum, _max_arrivals(tab.eta[sectors], mode, ctx.minute0, H), city.dist, dist_t, hop_t,
    )
    # With a tail the agent's end position is part of every cost: no candidate's cost is another's.
    shadow = (cands != PICKUP) & (sc.shadow and greedy and not cfg.tail and not cfg.place)
    place = place_values(city, tab, sectors) if cfg.place else _NO_PLACE
    home = np.ascontiguousarray(ctx.home[taxis]) if ctx.home.size else _NO_HOME
    return _Inputs(cands=cands, skip=skip, args=args, ag=ag, shadow=np.ascontiguousarray(shadow), place=place, home=home)


_NO_PLACE = np.empty(0, dtype=np.int64)


def cap_ranking(city: City, obs: Observation, here: int, taxis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The order in which the cap keeps ``taxis``, nearest to ``here`` first (hops, either direction; lower id on ties), and their hops."""
    d = np.minimum(city.dist[here, obs.pos[taxis]], city.dist[obs.pos[taxis], here])
    return np.lexsort((taxis, d)), d


def _pickup_spots(ctx: StepContext, sectors: np.ndarray, rel_node: np.ndarray, tracked_pickups: np.ndarray) -> np.ndarray:
    """Nodes where a rollout can pick up: the tracked requests' and every possible arrival's (relevant) pickup node.

    Only whether a taxi reaches one of them matters (:func:`K.reaches`), so
    the list may repeat a node; the arrivals' nodes are found once per minute
    and set of sectors.
    """
    key = sectors.tobytes()
    arrivals = ctx.arrival_spots.get(key)
    if arrivals is None:
        tab, minute0 = ctx.tables, ctx.minute0
        eta = tab.eta[sectors]
        if CE_MODES[ctx.config.ce] == K.LIMITED_CE:
            live = sectors[eta > 0]
        else:
            m = minute0 + ctx.config.horizon
            live = sectors[np.floor(eta * (m + 1) + 0.5) - np.floor(eta * (minute0 + 1) + 0.5) > 0]
        parts = [tab.pk_node[tab.pk_ptr[q] : tab.pk_ptr[q + 1]] for q in live]
        arrivals = np.unique(np.concatenate(parts).astype(np.int32)) if parts else np.empty(0, np.int32)
        ctx.arrival_spots[key] = arrivals
    nodes = np.concatenate((tracked_pickups.astype(np.int32), arrivals))
    return np.ascontiguousarray(nodes[rel_node[nodes]])


def _run(ctx: StepContext, inp: _Inputs, s_lo: int, s_hi: int, active: np.ndarray, serial: bool = False) -> tuple[np.ndarray, np.ndarray]:
    if serial:
        return K.rollout_costs_serial(*kernel_args(ctx, inp, s_lo, s_hi, active), 1)
    threads = numba.get_num_threads()
    return K.rollout_costs(*kernel_args(ctx, inp, s_lo, s_hi, active), 8 * threads, threads)


def kernel_args(ctx: StepContext, inp: _Inputs, s_lo: int, s_hi: int, active: np.ndarray) -> tuple:
    """The arguments of either rollout kernel for samples ``s_lo … s_hi-1`` of a decision, all but the chunk count."""
    cfg = ctx.config
    return (BASES[cfg.base], cfg.horizon, s_lo, s_hi, active, inp.shadow, ctx.shortcuts.share, inp.ag, cfg.tail, cfg.cycle, cfg.place, inp.place, inp.home, *inp.args)


def agent_costs(ctx: StepContext, committed: np.ndarray, agent: int) -> tuple[np.ndarray, np.ndarray]:
    """Candidate controls of a free agent and their rollout cost in every sample.

    Parameters
    ----------
    ctx : StepContext
    committed : ndarray
        Controls already committed by agents ``0 … agent-1``.
    agent : int

    Returns
    -------
    candidates : ndarray (C,)
    costs : ndarray of int32, shape (C, samples)
        Rollout cost of each candidate in each sample (common random numbers),
        the same with or without the exact shortcuts.
    """
    inp = _decision_inputs(ctx, committed, agent)
    costs, _ = _run(ctx, inp, 0, ctx.config.samples, np.ones(inp.cands.size, dtype=bool))
    return inp.cands, costs


def _max_arrivals(eta: np.ndarray, mode: int, minute0: int, horizon: int) -> int:
    """An upper bound on one sample's arrivals from sectors with rates ``eta``."""
    if mode == K.LIMITED_CE:
        per_minute = np.where(eta >= 1.0, np.floor(eta + 0.5), 1.0)
        return int(per_minute.sum()) * horizon
    m = minute0 + horizon
    return int((np.floor(eta * (m + 1) + 0.5) - np.floor(eta * (minute0 + 1) + 0.5)).sum())


def choose(cands: np.ndarray, costs: np.ndarray) -> int:
    """The candidate of least total cost over samples; the first in ``cands`` order on ties."""
    totals = costs.sum(axis=1, dtype=np.int64)
    return int(cands[int(np.argmin(totals))])


#: Chunks of samples an agent that shares its host's cores runs, each on the threads its share allows then.
SHARE_CHUNKS = 4


def plan_agent(ctx: StepContext, committed: np.ndarray, agent: int, threads: Callable[[], int] | None = None) -> int:
    """One agent's rollout control: a pure function of the context, ``committed`` and ``agent``.

    A busy agent gets its forced next hop without planning.  With
    ``config.adaptive`` the samples run in batches and candidates are dropped
    on the way (:func:`adaptive_choice`); otherwise the choice is
    :func:`choose` over every sample, whatever exact shortcuts are on.
    ``threads``, when given, is asked before each of :data:`SHARE_CHUNKS`
    chunks of samples (or each adaptive batch) how many kernel threads to run
    it on (one: on the calling thread alone, :func:`_serial_now`;
    :class:`agents.cores.CoreShare`, :meth:`agents.rollout_policy.RolloutPolicy._act_waves`);
    the control does not depend on it.
    """
    return _plan(ctx, committed, agent, serial=False, threads=threads)


def _plan(ctx: StepContext, committed: np.ndarray, agent: int, serial: bool, threads: Callable[[], int] | None = None) -> int:
    """:func:`plan_agent`; ``serial`` runs the samples in the calling thread without the GIL (same result)."""
    if ctx.obs.tau[agent] > 0:
        return int(ctx.base_controls[agent])
    inp = _decision_inputs(ctx, committed, agent)
    n_c, S = inp.cands.size, ctx.config.samples
    if inp.skip:
        ctx.stats.add(True, False, 0, 0)
        return int(inp.cands[0])
    if ctx.config.adaptive is not None:
        return adaptive_choice(ctx, inp, serial, threads)
    if threads is None or serial:
        costs, settled = _run(ctx, inp, 0, S, np.ones(n_c, dtype=bool), serial)
    else:
        parts = [_run(ctx, inp, c * S // SHARE_CHUNKS, (c + 1) * S // SHARE_CHUNKS, np.ones(n_c, dtype=bool), _serial_now(False, threads))
                 for c in range(SHARE_CHUNKS)]
        costs, settled = (np.concatenate(x, axis=1) for x in zip(*parts))
    shadowed = int(settled.sum())
    ctx.stats.add(False, n_c > 1 and shadowed == (n_c - 1) * S, n_c * S - shadowed, shadowed)
    return choose(inp.cands, costs)


def adaptive_choice(ctx: StepContext, inp: _Inputs, serial: bool = False, threads: Callable[[], int] | None = None) -> int:
    """Successive elimination with common random numbers, deterministic for a seed.

    After each batch, the best candidate is the one of least total cost over
    the samples so far among those left (first in order on ties); another is
    dropped when the mean of its paired differences from the best exceeds
    ``adaptive`` standard errors of that mean (:func:`agents._adaptive.eliminate`).
    Stops when one is left or the samples are used up, and returns the best
    of those left.  Each batch runs on the kernel threads, or on those
    ``threads`` allows then, as :func:`plan_agent`'s chunks do; ``serial``
    runs them in the calling thread.
    """
    cfg = ctx.config
    n_c = inp.cands.size
    active = np.ones(n_c, dtype=bool)
    costs = np.zeros((n_c, cfg.samples), dtype=np.int64)
    run = shadowed = 0
    lo, left = 0, n_c
    while lo < cfg.samples and left > 1:
        hi = min(cfg.samples, lo + cfg.batch)
        part, settled = _run(ctx, inp, lo, hi, active, _serial_now(serial, threads))
        done = int(settled.sum())
        run += left * (hi - lo) - done
        shadowed += done
        costs[:, lo:hi] = part
        lo = hi
        left = eliminate(costs, lo, active, cfg.adaptive)
    ctx.stats.add(False, False, run, shadowed)
    return int(inp.cands[best_candidate(costs, lo, active)])


def _serial_now(serial: bool, threads: Callable[[], int] | None) -> bool:
    """Whether the next kernel call runs the serial kernel: if ``serial``, or if ``threads`` now allows one (else it runs on as many as allowed).

    A one-thread share runs the parallel kernel on one thread instead where
    :func:`_threadsafe_regions` allows it: it computes faster than the serial
    kernel (numba compiles the same loop body better inside a parallel
    region).  Agents side by side, in-process
    (:meth:`agents.rollout_policy.RolloutPolicy._act_waves`) or a fleet's
    processes on one host (:class:`agents.cores.CoreShare`), get it once
    they have run a region; a fleet's agent does when it warms its kernels
    up (:meth:`agents.taxi.TaxiAgent._warm_up`).  Their fork server never
    starts the layer (:mod:`agents.preload`).
    """
    if serial or threads is None:
        return serial
    n = threads()
    if n == 1 and not _threadsafe_regions():
        return True
    set_kernel_threads(n)
    return False


def _threadsafe_regions() -> bool:
    """Whether this process has started a threading layer that takes parallel regions from several threads at once (OpenMP, TBB; not workqueue)."""
    try:
        return numba.threading_layer() in ("omp", "tbb")
    except ValueError:
        return False


def set_kernel_threads(n: int) -> None:
    """Threads of this thread's rollout kernel, at most the cores numba sees; decisions do not depend on it (:func:`K.rollout_costs`).

    Agents that share a host plan side by side, each on fewer threads, rather
    than each spreading over every core at once.
    """
    if n < 1:
        raise ValueError(f"kernel threads must be at least 1, got {n}")
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))


def warm_up(city: City | None = None, config: RolloutConfig | None = None, serial: bool = False) -> None:
    """Plan once on a made-up minute with two samples: loads the compiled kernels, or compiles them on a fresh checkout.

    Launchers call it before spawning agents, so that numba compiles once into
    its on-disk cache instead of in every agent at the same time.  Any city
    serves (the embedded synthetic one by default): the kernels depend on
    types, not on the map.  ``serial`` plans in the calling thread and leaves
    the parallel kernel unloaded: its OpenMP runtime must not be running in a
    process that forks (:mod:`agents.preload`).
    """
    if city is None:
        from city.scenario import load_city

        city = load_city("synthetic")
    config = config or RolloutConfig()
    S, n = city.n_sectors, city.n_nodes
    nodes = np.flatnonzero(city.pickup)[:2].astype(np.int32)
    fc = Forecast(eta=np.full(S, 0.5), rho=np.ones(n), delta=np.ones(n), beta=np.ones((S, S)))
    cfg = replace(config, samples=2)
    obs = Observation(t=0, pos=nodes[:1], tau=np.zeros(1, np.int32), dest=np.full(1, -1, np.int32), req_index=np.zeros(1, np.int64),
                      req_pickup=nodes[:1], req_dropoff=nodes[-1:], req_entry=np.zeros(1, np.int32))
    hour = HourInputs.of(city, fc) if cfg.base == "rebalance" else None
    _plan(prepare_step(city, cfg, obs, DemandTables.build(city, fc, cfg.ce, cfg.seed), 0, hour=hour), np.empty(0, np.int32), 0, serial)
