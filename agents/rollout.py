"""One-agent-at-a-time rollout (paper §4.1, Eq. 2) and the two rollout policies.

At minute ``t`` the free taxis decide in agent order.  Agent ℓ scores each
control of its control set (stay, pickup when a request waits at its node,
each out-neighbour): agents before it use their committed controls, agents
after it the base policy's control for the current minute, and then the
base policy runs for every taxi for ``H`` more minutes on requests sampled
from the forecast.  The cost of a rollout is the sum of the stage costs (the
requests outstanding after each minute) plus a terminal cost, the requests
still outstanding at the end.  The agent takes the control of least Monte-Carlo
mean cost; ties go to staying, then to pickup, then to the lowest node id.
Busy taxis have a single control (their next hop) and are not planned.

Two policies are registered:

``surge`` (the paper's method)
    Greedy base policy; limited certainty equivalence (η rounded when at
    least one request per minute, a Bernoulli draw below); requests sampled
    only in the agent's sector and its adjacent sectors; forecast ``model``
    by default.
``garces2023`` (Garces et al. 2023, the paper's baseline 3)
    Instantaneous-assignment base policy; standard certainty equivalence;
    requests sampled over the whole map; forecast ``previous-hour``.

Standard certainty equivalence, as implemented here: η is replaced by its
mean, so a sector receives its requests deterministically, one each time the
rounded cumulative mean ``⌊η · m + ½⌋`` steps up (``m`` minutes since the hour
began).  ρ and δ are replaced by a pre-computed pool per sector, drawn once
per forecast from ρ (pickups, about ``60 η`` of them, like an hour of past
requests) and δ (drop-offs, about the hour's expected drop-offs).  Each
sample draws every request's pickup from its sector's pool, its drop-off
sector from β and its drop-off from that sector's pool, independently, so β
and the order in which requests arrive stay stochastic.

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
Every shortcut but pruning is exact (``tests/test_rollout.py`` compares the
costs with the simulator); pruning is validated there to reproduce the
unpruned decisions on seeded states.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

import numba
import numpy as np

from agents import _kernels as K
from agents.base import EpisodeContext, Option, Policy, register
from agents.forecast import PROVIDERS, Forecast, ForecastProvider, make_provider
from agents.greedy import greedy_controls
from agents.ia import ia_controls
from city.errors import ConfigError
from city.graph import City
from city.sim import PICKUP, Observation

BASES = {"greedy": K.GREEDY, "ia": K.IA}
SCOPES = ("local", "map")
CE_MODES = {"limited": K.LIMITED_CE, "standard": K.STANDARD_CE}
#: Nearest tracked requests listed per node; searches past them scan all tracked requests.
NEAR_K = 8


@dataclass(frozen=True)
class RolloutConfig:
    """Parameters of a rollout planner.

    Attributes
    ----------
    horizon : int
        H, minutes of base policy after the decision minute.
    samples : int
        Monte-Carlo samples per agent decision.
    base : str
        Base policy: ``greedy`` or ``ia``.
    scope : str
        Where future requests are sampled: ``local`` (the agent's sector and
        its adjacent sectors) or ``map`` (every sector).
    ce : str
        Certainty equivalence: ``limited`` (surge) or ``standard`` (Garces et al.).
    seed : int
        Seed of every decision's random numbers.
    prune : int or None
        Leave out taxis and requests farther than this many hops (either
        direction) from the deciding agent; ``None`` simulates the whole map.
    """

    horizon: int = 10
    samples: int = 1000
    base: str = "greedy"
    scope: str = "local"
    ce: str = "limited"
    seed: int = 0
    prune: int | None = None

    def __post_init__(self) -> None:
        if self.horizon < 1 or self.samples < 1:
            raise ConfigError(f"rollout: horizon and samples must be at least 1, got {self.horizon} and {self.samples}")
        if self.base not in BASES:
            raise ConfigError(f"rollout: unknown base policy {self.base!r}; choose from {', '.join(BASES)}")
        if self.scope not in SCOPES:
            raise ConfigError(f"rollout: unknown scope {self.scope!r}; choose from {', '.join(SCOPES)}")
        if self.ce not in CE_MODES:
            raise ConfigError(f"rollout: unknown certainty equivalence {self.ce!r}; choose from {', '.join(CE_MODES)}")
        if self.prune is not None and self.prune < 0:
            raise ConfigError(f"rollout: prune radius must be non-negative, got {self.prune}")


def default_prune(horizon: int) -> int:
    """The default pruning radius: twice the hops a taxi covers in a rollout, ``2 (H + 1)``."""
    return 2 * (horizon + 1)


@dataclass(frozen=True)
class DemandTables:
    """A forecast laid out for the sampling kernel.

    Attributes
    ----------
    eta : ndarray (S,)
        Per-minute rate (zero for sectors without pickup intersections).
    pk_ptr, pk_node, pk_cum : ndarray
        Per sector (CSR by ``pk_ptr``), the pickup nodes and their cumulative weights.
    dk_ptr, dk_node, dk_cum : ndarray
        The same for drop-off nodes.
    beta_cum : ndarray (S, S)
        Cumulative drop-off-sector weights per pickup sector.
    """

    eta: np.ndarray
    pk_ptr: np.ndarray
    pk_node: np.ndarray
    pk_cum: np.ndarray
    dk_ptr: np.ndarray
    dk_node: np.ndarray
    dk_cum: np.ndarray
    beta_cum: np.ndarray

    @classmethod
    def build(cls, city: City, forecast: Forecast, ce: str, seed: int) -> DemandTables:
        """Tables of ``forecast``: the distributions themselves (limited CE) or per-sector pools (standard CE)."""
        S, n = city.n_sectors, city.n_nodes
        if forecast.n_sectors != S or forecast.rho.shape[0] != n:
            raise ConfigError(f"forecast has {forecast.n_sectors} sectors and {forecast.rho.shape[0]} nodes; the city has {S} and {n}")
        eligible = np.asarray(city.pickup, dtype=bool)
        has_nodes = np.bincount(city.node_sector[eligible], minlength=S) > 0
        eta = np.where(has_nodes, forecast.eta, 0.0)
        beta = np.where(has_nodes[None, :], forecast.beta, 0.0)
        beta = np.where(beta.sum(1, keepdims=True) > 0, beta, has_nodes[None, :].astype(np.float64))
        if ce == "standard":
            rng = np.random.default_rng([seed, 2023])
            drop_expect = 60.0 * (eta @ (beta / beta.sum(1, keepdims=True)))
            pick = _pools(city, forecast.rho, np.maximum(1, np.rint(60.0 * eta)).astype(np.int64), rng)
            drop = _pools(city, forecast.delta, np.maximum(1, np.rint(drop_expect)).astype(np.int64), rng)
        else:
            pick = _tables(city, forecast.rho)
            drop = _tables(city, forecast.delta)
        return cls(eta=np.ascontiguousarray(eta, dtype=np.float64), pk_ptr=pick[0], pk_node=pick[1], pk_cum=pick[2],
                   dk_ptr=drop[0], dk_node=drop[1], dk_cum=drop[2], beta_cum=np.ascontiguousarray(np.cumsum(beta, axis=1)))


def _weights(city: City, p: np.ndarray) -> np.ndarray:
    """``p`` on eligible nodes, uniform within sectors where it has no mass."""
    eligible = np.asarray(city.pickup, dtype=bool)
    w = np.where(eligible, p, 0.0)
    mass = np.bincount(city.node_sector, weights=w, minlength=city.n_sectors)
    return np.where(mass[city.node_sector] > 0, w, eligible.astype(np.float64))


def _tables(city: City, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    w = _weights(city, p)
    nodes = np.flatnonzero(w > 0)
    nodes = nodes[np.argsort(city.node_sector[nodes], kind="stable")]
    sec = city.node_sector[nodes]
    ptr = np.searchsorted(sec, np.arange(city.n_sectors + 1)).astype(np.int64)
    cum = np.empty(nodes.size, dtype=np.float64)
    for s in range(city.n_sectors):
        cum[ptr[s] : ptr[s + 1]] = np.cumsum(w[nodes[ptr[s] : ptr[s + 1]]])
    return ptr, nodes.astype(np.int32), cum


def _pools(city: City, p: np.ndarray, sizes: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A pool of ``sizes[s]`` nodes per sector drawn from ``p``, as uniform-weight tables."""
    ptr, nodes, cum = _tables(city, p)
    parts, counts = [], np.zeros(city.n_sectors, dtype=np.int64)
    for s in range(city.n_sectors):
        lo, hi = ptr[s], ptr[s + 1]
        if hi == lo:
            continue
        idx = np.searchsorted(cum[lo:hi], rng.random(int(sizes[s])) * cum[hi - 1], side="right")
        parts.append(nodes[lo + np.minimum(idx, hi - lo - 1)])
        counts[s] = sizes[s]
    pool = np.concatenate(parts).astype(np.int32)
    pool_ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    pool_cum = np.concatenate([np.arange(1, c + 1, dtype=np.float64) for c in counts if c])
    return pool_ptr, pool, pool_cum


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
    """

    city: City
    config: RolloutConfig
    obs: Observation
    base_controls: np.ndarray
    tables: DemandTables
    minute0: int


def base_controls(city: City, config: RolloutConfig, obs: Observation) -> np.ndarray:
    """The base policy's joint control for the minute: what agents after the decider play, and a silent agent's fallback."""
    base = greedy_controls(city, obs) if config.base == "greedy" else ia_controls(city, obs)
    return base.astype(np.int32)


def prepare_step(city: City, config: RolloutConfig, obs: Observation, tables: DemandTables, minute0: int) -> StepContext:
    """The shared per-minute context: the base policy's joint control."""
    return StepContext(city, config, obs, base_controls(city, config, obs), tables, int(minute0))


def candidate_controls(city: City, obs: Observation, agent: int) -> np.ndarray:
    """Agent's control set in tie-break order: stay, pickup (if a request waits here), out-neighbours ascending."""
    here = int(obs.pos[agent])
    cands = [here]
    if np.any(obs.req_pickup == here):
        cands.append(PICKUP)
    cands.extend(sorted(int(v) for v in city.neighbors(here)))
    return np.asarray(cands, dtype=np.int32)


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
        Rollout cost of each candidate in each sample (common random numbers).
    """
    city, cfg, obs = ctx.city, ctx.config, ctx.obs
    if obs.tau[agent] > 0:
        raise ValueError(f"agent {agent} is busy; its only control is its next hop")
    committed = np.asarray(committed, dtype=np.int32)
    if committed.shape != (agent,):
        raise ValueError(f"committed: expected {agent} controls, got {committed.shape}")
    H = cfg.horizon
    here = int(obs.pos[agent])
    cands = candidate_controls(city, obs, agent)
    controls = np.repeat(ctx.base_controls[None, :], cands.size, axis=0)
    controls[:, :agent] = committed
    controls[:, agent] = cands
    req_pick = np.ascontiguousarray(obs.req_pickup, dtype=np.int32)
    req_drop = np.ascontiguousarray(obs.req_dropoff, dtype=np.int32)
    alive0, pos1, tfree1 = K.step_zero(controls, obs.pos, obs.tau, obs.dest, req_pick, req_drop, city.dist)

    if cfg.prune is None:
        rel_node = np.ones(city.n_nodes, dtype=bool)
    else:
        rel_node = (city.dist[here] <= cfg.prune) | (city.dist[:, here] <= cfg.prune)
    tracked = np.flatnonzero(rel_node[req_pick])
    keep = (tfree1.min(axis=0) <= H) & rel_node[pos1].any(axis=0)
    keep[agent] = True
    taxis = np.flatnonzero(keep)
    near, near_d = K.nearest_lists(city.dist, req_pick[tracked], NEAR_K)

    if cfg.scope == "local":
        sectors = city.local_sectors(int(city.node_sector[here]))
    else:
        sectors = np.arange(city.n_sectors)
    if cfg.prune is not None:
        sectors = sectors[np.bincount(city.node_sector[rel_node], minlength=city.n_sectors)[sectors] > 0]
    tab = ctx.tables
    mode = CE_MODES[cfg.ce]
    costs = K.rollout_costs(
        BASES[cfg.base], H, cfg.samples, np.uint64(K.stream_key(cfg.seed, int(obs.t), agent)), ctx.minute0, mode,
        np.ascontiguousarray(alive0[:, tracked]), np.ascontiguousarray(pos1[:, taxis]), np.ascontiguousarray(tfree1[:, taxis]),
        req_pick[tracked], req_drop[tracked], near, near_d, rel_node,
        sectors.astype(np.int64), tab.eta, tab.pk_ptr, tab.pk_node, tab.pk_cum, tab.dk_ptr, tab.dk_node, tab.dk_cum,
        tab.beta_cum, _max_arrivals(tab.eta[sectors], mode, ctx.minute0, H), city.dist, city.next_hop,
        8 * numba.get_num_threads(),
    )
    return cands, costs


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


def plan_agent(ctx: StepContext, committed: np.ndarray, agent: int) -> int:
    """One agent's rollout control: a pure function of the context, ``committed`` and ``agent``.

    A busy agent gets its forced next hop without planning.
    """
    if ctx.obs.tau[agent] > 0:
        return int(ctx.base_controls[agent])
    cands, costs = agent_costs(ctx, committed, agent)
    return choose(cands, costs)


def warm_up(city: City | None = None, config: RolloutConfig | None = None) -> None:
    """Plan once on a made-up minute with two samples: loads the compiled kernels, or compiles them on a fresh checkout.

    Launchers call it before spawning agents, so that numba compiles once into
    its on-disk cache instead of in every agent at the same time.  Any city
    serves (the embedded synthetic one by default): the kernels depend on
    types, not on the map.
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
    plan_agent(prepare_step(city, cfg, obs, DemandTables.build(city, fc, cfg.ce, cfg.seed), 0), np.empty(0, np.int32), 0)


class RolloutPolicy(Policy):
    """One-agent-at-a-time rollout with a forecast provider; subclasses fix the defaults.

    Parameters
    ----------
    city : City
    forecast : str
        Forecast provider name (``model``, ``previous-hour``, ``true-rate``).
    model : str or Path, optional
        Trained predictor directory for ``forecast="model"``.
    horizon, samples, base, scope, ce, seed :
        See :class:`RolloutConfig`.
    prune : int or None or "auto"
        Pruning radius in hops; ``"auto"`` is :func:`default_prune` of the horizon.
    """

    defaults: ClassVar[dict[str, Any]] = {}
    options = (
        Option("forecast", str, choices=tuple(sorted(PROVIDERS)), help="forecast provider"),
        Option("model", str, noun="a directory", help="trained predictor directory for forecast=model"),
        Option("horizon", int, low=1, high=240, help="H, minutes of base policy after the decision minute"),
        Option("samples", int, low=1, high=1_000_000, help="Monte-Carlo samples per agent decision"),
        Option("base", str, choices=tuple(BASES), help="base policy"),
        Option("scope", str, choices=SCOPES, help="where future requests are sampled"),
        Option("ce", str, choices=tuple(CE_MODES), help="certainty equivalence"),
        Option("seed", int, low=0, help="seed of every decision's random numbers"),
        Option("prune", int, low=0, words={"auto": "auto", "none": None}, help="pruning radius in hops"),
    )

    def __init__(self, city: City, forecast: str | None = None, model: str | Path | None = None, **planner: Any) -> None:
        super().__init__(city)
        try:
            self.config = self.rollout_config(**planner)
        except TypeError as exc:
            raise ConfigError(f"policy {self.name!r}: {exc}") from None
        self.provider: ForecastProvider = make_provider(forecast or self.defaults["forecast"], model)
        self.context: EpisodeContext | None = None
        self._tables: dict[int, DemandTables] = {}

    @classmethod
    def rollout_config(
        cls,
        horizon: int | None = None,
        samples: int | None = None,
        base: str | None = None,
        scope: str | None = None,
        ce: str | None = None,
        seed: int | None = None,
        prune: int | str | None = "auto",
    ) -> RolloutConfig:
        """The planner settings of this policy with ``None`` options at its defaults; no forecast is loaded."""
        d = cls.defaults
        H = int(horizon if horizon is not None else d["horizon"])
        return RolloutConfig(
            horizon=H,
            samples=int(samples if samples is not None else d["samples"]),
            base=base or d["base"],
            scope=scope or d["scope"],
            ce=ce or d["ce"],
            seed=int(seed if seed is not None else 0),
            prune=default_prune(H) if prune == "auto" else (None if prune is None else int(prune)),
        )

    def reset(self, context: EpisodeContext) -> None:
        if context.world is None:
            raise ConfigError(f"policy {self.name!r} needs the episode's demand world for its forecasts")
        self.context = context
        self._tables = {}

    def forecast(self, hour_offset: int) -> Forecast:
        """The provider's forecast of the hour ``hour_offset`` hours after the episode's start."""
        ctx = self.context
        assert ctx is not None, "reset() must be called before act()"
        when = dt.datetime.combine(ctx.date, dt.time()) + dt.timedelta(hours=ctx.hour + hour_offset)
        return self.provider.forecast(ctx.world, when)

    def tables(self, hour_offset: int) -> DemandTables:
        """Demand tables for the hour ``hour_offset`` hours after the episode's start."""
        if hour_offset not in self._tables:
            self._tables[hour_offset] = DemandTables.build(self.city, self.forecast(hour_offset), self.config.ce, self.config.seed)
        return self._tables[hour_offset]

    def step_context(self, obs: Observation) -> StepContext:
        """The shared context of minute ``obs.t``."""
        return prepare_step(self.city, self.config, obs, self.tables(obs.t // 60), obs.t % 60)

    def act(self, obs: Observation) -> np.ndarray:
        ctx = self.step_context(obs)
        u = ctx.base_controls.copy()
        for agent in np.flatnonzero(obs.tau == 0):
            u[agent] = plan_agent(ctx, u[:agent], int(agent))
        return u


@register
class Surge(RolloutPolicy):
    """The paper's method: greedy base, limited CE, local sampling, event-informed forecast."""

    name = "surge"
    defaults: ClassVar[dict[str, Any]] = {"forecast": "model", "horizon": 10, "samples": 1000, "base": "greedy", "scope": "local", "ce": "limited"}


@register
class Garces2023(RolloutPolicy):
    """Garces et al. (2023): IA base, standard CE, whole-map sampling, previous-hour demand."""

    name = "garces2023"
    defaults: ClassVar[dict[str, Any]] = {"forecast": "previous-hour", "horizon": 10, "samples": 1000, "base": "ia", "scope": "map", "ce": "standard"}
