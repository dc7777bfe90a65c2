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
from dataclasses import dataclass, replace

import numba
import numpy as np

from agents import _kernels as K
from agents._adaptive import best_candidate, eliminate, paired_stats
from agents.demand_tables import DemandTables
from agents.greedy import greedy_controls
from agents.ia import ia_controls
from agents.kernel_threads import serial_now
from agents.rollout_config import BASES, RolloutConfig
from agents.rollout_inputs import NO_HOME, DecisionInputs, StepContext, decision_inputs
from agents.shortcuts import MINUTE_NEAR_K, Shortcuts
from city.errors import ConfigError
from city.forecast import Forecast
from city.graph import City
from city.sim import Observation


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
    return base.astype(np.int32), NO_HOME


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
        home = NO_HOME
    return StepContext(city, config, obs, base, tables, int(minute0), sc, near, near_d, home=home)


def _run(ctx: StepContext, inp: DecisionInputs, s_lo: int, s_hi: int, active: np.ndarray, serial: bool = False) -> tuple[np.ndarray, np.ndarray]:
    if serial:
        return K.rollout_costs_serial(*kernel_args(ctx, inp, s_lo, s_hi, active), 1)
    threads = numba.get_num_threads()
    return K.rollout_costs(*kernel_args(ctx, inp, s_lo, s_hi, active), 8 * threads, threads)


def kernel_args(ctx: StepContext, inp: DecisionInputs, s_lo: int, s_hi: int, active: np.ndarray) -> tuple:
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
    inp = decision_inputs(ctx, committed, agent)
    costs, _ = _run(ctx, inp, 0, ctx.config.samples, np.ones(inp.cands.size, dtype=bool))
    return inp.cands, costs


def least_total(costs: np.ndarray) -> int:
    """The index of the candidate of least total cost over samples; the first on ties."""
    return int(np.argmin(costs.sum(axis=1, dtype=np.int64)))


def choose(cands: np.ndarray, costs: np.ndarray) -> int:
    """The candidate of least total cost over samples; the first in ``cands`` order on ties."""
    return int(cands[least_total(costs)])


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
    it on (one: on the calling thread alone, :func:`agents.kernel_threads.serial_now`;
    :class:`agents.cores.CoreShare`, :meth:`agents.rollout_policy.RolloutPolicy._act_waves`);
    the control does not depend on it.
    """
    return _plan(ctx, committed, agent, serial=False, threads=threads)


def _plan(ctx: StepContext, committed: np.ndarray, agent: int, serial: bool, threads: Callable[[], int] | None = None) -> int:
    """:func:`plan_agent`; ``serial`` runs the samples in the calling thread without the GIL (same result)."""
    if ctx.obs.tau[agent] > 0:
        return int(ctx.base_controls[agent])
    inp = decision_inputs(ctx, committed, agent)
    n_c, S = inp.cands.size, ctx.config.samples
    if inp.skip:
        ctx.stats.add(True, False, 0, 0)
        # No candidate can change a cost: with ``keep`` that is no margin at all, so the base's control.
        b = base_candidate(ctx, inp.cands, agent) if ctx.config.keep is not None else None
        return int(inp.cands[0 if b is None else b])
    if ctx.config.adaptive is not None:
        return adaptive_choice(ctx, inp, agent, serial, threads)
    if threads is None or serial:
        costs, settled = _run(ctx, inp, 0, S, np.ones(n_c, dtype=bool), serial)
    else:
        parts = [_run(ctx, inp, c * S // SHARE_CHUNKS, (c + 1) * S // SHARE_CHUNKS, np.ones(n_c, dtype=bool), serial_now(False, threads))
                 for c in range(SHARE_CHUNKS)]
        costs, settled = (np.concatenate(x, axis=1) for x in zip(*parts))
    shadowed = int(settled.sum())
    ctx.stats.add(False, n_c > 1 and shadowed == (n_c - 1) * S, n_c * S - shadowed, shadowed)
    return int(inp.cands[kept(ctx, inp.cands, costs, np.full(n_c, S), least_total(costs), agent)])


def base_candidate(ctx: StepContext, cands: np.ndarray, agent: int) -> int | None:
    """The index in ``cands`` of the base policy's control for ``agent``, or ``None`` where it is not a candidate."""
    at = np.flatnonzero(cands == ctx.base_controls[agent])
    return int(at[0]) if at.size else None


def kept(ctx: StepContext, cands: np.ndarray, costs: np.ndarray, ran: np.ndarray, best: int, agent: int) -> int:
    """The index of the candidate chosen: ``best``, or with ``config.keep`` the base policy's control unless ``best`` beats it by more than ``keep`` standard errors.

    The paired differences are taken over the first ``ran[b]`` samples, those
    the base's candidate ``b`` ran before elimination dropped it; ``best`` wins
    exactly when :func:`agents._adaptive.eliminate` at ``keep`` would drop ``b``.
    """
    z = ctx.config.keep
    b = None if z is None else base_candidate(ctx, cands, agent)
    if b is None or b == best:
        return best
    n = int(ran[b])
    if n < 2:
        return b
    mean, se = paired_stats(np.asarray(costs, dtype=np.int64), n, best)
    return best if mean[b] - z * se[b] > 0 else b


def adaptive_choice(ctx: StepContext, inp: DecisionInputs, agent: int, serial: bool = False,
                    threads: Callable[[], int] | None = None) -> int:
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
    ran = np.zeros(n_c, dtype=np.int64)
    run = shadowed = 0
    lo, left = 0, n_c
    while lo < cfg.samples and left > 1:
        hi = min(cfg.samples, lo + cfg.batch)
        part, settled = _run(ctx, inp, lo, hi, active, serial_now(serial, threads))
        done = int(settled.sum())
        run += left * (hi - lo) - done
        shadowed += done
        costs[:, lo:hi] = part
        ran[active] = hi
        lo = hi
        left = eliminate(costs, lo, active, cfg.adaptive)
    ctx.stats.add(False, False, run, shadowed)
    return int(inp.cands[kept(ctx, inp.cands, costs, ran, best_candidate(costs, lo, active), agent)])


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
