"""The two rollout policies: ``surge`` (the paper's method) and ``garces2023`` (its baseline).

Both plan every free taxi with :func:`agents.rollout.plan_agent`; they differ
in their defaults.

``surge`` (the paper's method, planned further)
    Rolled out over ``rebalance`` (optimal matching plus forecast-driven
    rebalancing) for 20 minutes, requests sampled over the whole map, limited
    certainty equivalence (η rounded when at least one request per minute, a
    Bernoulli draw below), forecast ``model`` by default; planned with three
    approximations (200 samples, ``cap=12``, ``adaptive=1`` in batches of
    50); an agent keeps the base's control unless a candidate beats it by 2
    standard errors (``keep=2``).  Chosen on validation data over the paper's
    configuration (benchmarks/rollout-variants/, benchmarks/practice-baselines/).
    :data:`PAPER` is the paper's configuration (greedy base, H = 10, local
    sampling, 1,000 samples, planned exactly, no ``keep``); ``surge
    reproduce`` plans so.
``garces2023`` (Garces et al. 2023, the paper's baseline 3)
    Instantaneous-assignment base policy; standard certainty equivalence;
    requests sampled over the whole map; forecast ``previous-hour``.

Independent agents can plan at once (:mod:`agents.waves`, the policy's
``workers``), with the decisions of strictly sequential turns.
"""

from __future__ import annotations

import datetime as dt
import heapq
import threading
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from pathlib import Path
from typing import Any, ClassVar

import numba
import numpy as np

from agents.base import EpisodeContext, Option, Policy, register, split_policy
from agents.demand_tables import DemandTables
from agents.forecast_providers import PROVIDERS, make_provider
from agents.rollout import HourInputs, StepContext, plan_agent, prepare_step
from agents.rollout_config import BASES, CE_MODES, SCOPES, RolloutConfig, default_prune
from agents.shortcuts import PlanStats, Shortcuts
from agents.waves import plan_waves
from city.errors import ConfigError
from city.forecast import Forecast, ForecastProvider
from city.graph import City
from city.sim import Observation

#: ``cap`` or ``adaptive`` not given: the policy's default, which may be on (``None`` is off).
DEFAULT = object()


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
    cap, adaptive, batch :
        Approximations (see :class:`RolloutConfig`); ``None`` turns one off,
        and an option not given takes the policy's default.
    workers : int, optional
        Threads planning independent agents at once (:mod:`agents.waves`,
        :meth:`_act_waves`); 1 (the default) plans one agent at a time with
        the samples in parallel.  The decisions are the same either way.

    Attributes
    ----------
    shortcuts : Shortcuts
        Exact savings in use (all); benchmarks and tests switch them off to compare.
    last_stats : PlanStats or None
        The counters of the last :meth:`act`.
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
        Option("cap", int, low=1, words={"none": None}, help="approximation: simulate only the agent's k nearest taxis"),
        Option("adaptive", float, low=0, open_low=True, words={"none": None},
               help="approximation: drop a candidate once it trails the best by this many standard errors"),
        Option("batch", int, low=2, help="samples per batch of adaptive"),
        Option("tail", int, low=0, high=240, help="minutes after the horizon valued by a fluid terminal cost (0: none)"),
        Option("cycle", int, low=1, high=240, help="minutes per pickup of a taxi in the tail"),
        Option("place", int, low=0, high=1000, help="tenths of a request-minute per hop of the free taxis' end distance to forecast demand (0: none)"),
        Option("keep", float, low=0, words={"none": None},
               help="keep the base policy's control unless a candidate beats it by this many standard errors"),
        Option("workers", int, low=1, help="threads planning independent agents of a minute concurrently"),
    )
    shortcuts: Shortcuts = Shortcuts()
    last_stats: PlanStats | None = None

    def __init__(self, city: City, forecast: str | None = None, model: str | Path | None = None, workers: int | None = None,
                 **planner: Any) -> None:
        super().__init__(city)
        self.workers = int(workers) if workers is not None else 1
        if self.workers < 1:
            raise ConfigError(f"policy {self.name!r}: workers must be at least 1, got {workers}")
        try:
            self.config = self.rollout_config(**planner)
        except TypeError as exc:
            raise ConfigError(f"policy {self.name!r}: {exc}") from None
        self.provider: ForecastProvider = make_provider(forecast or self.defaults["forecast"], model)
        self.context: EpisodeContext | None = None
        self._tables: dict[int, DemandTables] = {}
        self._hour_inputs: dict[int, HourInputs] = {}
        self._forecasts: dict[int, Forecast] = {}
        self._pool = None
        self.last_waves = None

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
        cap: int | None | object = DEFAULT,
        adaptive: float | None | object = DEFAULT,
        batch: int | None = None,
        tail: int | None = None,
        cycle: int | None = None,
        place: int | None = None,
        keep: float | None | object = DEFAULT,
    ) -> RolloutConfig:
        """The planner settings of this policy with the options not given at its defaults; no forecast is loaded.

        ``cap`` and ``adaptive`` take ``None`` for "off", so their default is
        :data:`DEFAULT` rather than ``None``.
        """
        d = cls.defaults
        cap = d["cap"] if cap is DEFAULT else cap
        adaptive = d["adaptive"] if adaptive is DEFAULT else adaptive
        keep = d.get("keep") if keep is DEFAULT else keep
        H = int(horizon if horizon is not None else d["horizon"])
        return RolloutConfig(
            horizon=H,
            samples=int(samples if samples is not None else d["samples"]),
            base=base or d["base"],
            scope=scope or d["scope"],
            ce=ce or d["ce"],
            seed=int(seed if seed is not None else 0),
            prune=default_prune(H) if prune == "auto" else (None if prune is None else int(prune)),
            cap=None if cap is None else int(cap),
            adaptive=None if adaptive is None else float(adaptive),
            batch=int(batch if batch is not None else d["batch"]),
            tail=int(tail if tail is not None else d.get("tail", 0)),
            cycle=int(cycle if cycle is not None else d.get("cycle", 10)),
            place=int(place if place is not None else d.get("place", 0)),
            keep=None if keep is None else float(keep),
        )

    def reset(self, context: EpisodeContext) -> None:
        if context.world is None:
            raise ConfigError(f"policy {self.name!r} needs the episode's demand world for its forecasts")
        self.context = context
        self._tables = {}
        self._hour_inputs = {}
        self._forecasts = {}

    def forecast(self, hour_offset: int) -> Forecast:
        """The provider's forecast of the hour ``hour_offset`` hours after the episode's start."""
        ctx = self.context
        assert ctx is not None, "reset() must be called before act()"
        when = dt.datetime.combine(ctx.date, dt.time()) + dt.timedelta(hours=ctx.hour + hour_offset)
        return self.provider.forecast(ctx.world, when)

    def _hour_forecast(self, hour_offset: int) -> Forecast:
        """:meth:`forecast`, asked of the provider once an hour for the tables and the rebalance base alike."""
        if hour_offset not in self._forecasts:
            self._forecasts[hour_offset] = self.forecast(hour_offset)
        return self._forecasts[hour_offset]

    def tables(self, hour_offset: int) -> DemandTables:
        """Demand tables for the hour ``hour_offset`` hours after the episode's start."""
        if hour_offset not in self._tables:
            self._tables[hour_offset] = DemandTables.build(self.city, self._hour_forecast(hour_offset), self.config.ce, self.config.seed)
        return self._tables[hour_offset]

    def hour_inputs(self, hour_offset: int) -> HourInputs | None:
        """The forecast's rates and sector anchors of an hour, which the ``rebalance`` base needs (``None`` for the other bases)."""
        if self.config.base != "rebalance":
            return None
        if hour_offset not in self._hour_inputs:
            self._hour_inputs[hour_offset] = HourInputs.of(self.city, self._hour_forecast(hour_offset))
        return self._hour_inputs[hour_offset]

    def step_context(self, obs: Observation) -> StepContext:
        """The shared context of minute ``obs.t``."""
        hour = obs.t // 60
        return prepare_step(self.city, self.config, obs, self.tables(hour), obs.t % 60, self.shortcuts, hour=self.hour_inputs(hour))

    def act(self, obs: Observation) -> np.ndarray:
        ctx = self.step_context(obs)
        u = ctx.base_controls.copy()
        if self.workers > 1:
            self._act_waves(ctx, u)
        else:
            for agent in np.flatnonzero(obs.tau == 0):
                u[agent] = plan_agent(ctx, u[:agent], int(agent))
        self.last_stats = ctx.stats
        return u

    def _act_waves(self, ctx: StepContext, u: np.ndarray) -> None:
        """Plan each agent once the agents it depends on have committed, up to ``workers`` at a time.

        This is the coordinator's release of turns (:mod:`agents.waves`), in
        threads: an agent's costs depend only on its ``depends``, so it plans
        with the controls committed so far and the result is that of strictly
        sequential turns.  An agent planning alone runs its samples on every
        kernel thread; while others plan too, each runs its chunks on one
        thread of its own (the kernel releases the GIL), so the cores do not
        idle.  That one thread is a one-thread parallel region where the
        threading layer allows several at once (OpenMP, TBB), and the serial
        kernel otherwise (:func:`agents.kernel_threads.serial_now`).

        Threads, not processes: the agents share the city and the minute's
        context, and only the short Python preparation of each decision is
        serialised.
        """
        waves = plan_waves(self.city, ctx.obs, self.config.prune)
        self.last_waves = waves
        if self._pool is None:
            self._pool = ThreadPoolExecutor(self.workers, thread_name_prefix="surge-plan")
        cores = numba.config.NUMBA_NUM_THREADS
        lock = threading.Lock()
        running = [0]

        def share() -> int:
            return cores if running[0] == 1 else 1

        def plan_one(agent: int, seen: np.ndarray) -> int:
            with lock:
                running[0] += 1
            try:
                return plan_agent(ctx, seen, agent, threads=share)
            finally:
                with lock:
                    running[0] -= 1

        waiting = {int(a): set(d.tolist()) for a, d in zip(waves.agents, waves.depends)}
        dependents = waves.dependents()
        ready = [a for a, d in waiting.items() if not d]
        heapq.heapify(ready)
        futures: dict = {}
        while ready or futures:
            while ready and len(futures) < self.workers:
                a = heapq.heappop(ready)
                futures[self._pool.submit(plan_one, a, u[:a].copy())] = a
            done, _ = wait(futures, return_when=FIRST_COMPLETED)
            for fut in done:
                a = futures.pop(fut)
                u[a] = fut.result()
                for b in dependents[a]:
                    waiting[b].discard(a)
                    if not waiting[b]:
                        heapq.heappush(ready, b)


#: The approximation options of exact planning, as ``garces2023`` plans (and ``surge`` in a results file that
#: records no ``surge_defaults``, written by surge 0.1).
EXACT: dict[str, Any] = {"cap": None, "adaptive": None, "batch": 100}

#: The paper's configuration besides the approximations: the greedy rollout, which always takes its best candidate
#: (no ``keep``).  An option a results file's ``surge_defaults`` does not record was planned with its value here.
GREEDY_ROLLOUT: dict[str, Any] = {"horizon": 10, "samples": 1000, "base": "greedy", "scope": "local", "keep": None}

#: The paper's method as the paper plans it: with these options a ``surge`` label plans as the paper does.
PAPER: dict[str, Any] = {**GREEDY_ROLLOUT, **EXACT}


@register
class Surge(RolloutPolicy):
    """The paper's method rolled out over ``rebalance`` for 20 minutes; limited CE, whole-map sampling, event-informed forecast.

    An agent keeps ``rebalance``'s control unless a candidate beats it by 2
    standard errors (``keep``), so sampling noise does not steer it off its base.
    The paper's own configuration is :data:`PAPER`.
    """

    name = "surge"
    defaults: ClassVar[dict[str, Any]] = {"forecast": "model", "horizon": 20, "samples": 200, "base": "rebalance", "scope": "map",
                                          "ce": "limited", "cap": 12, "adaptive": 1.0, "batch": 50, "keep": 2.0}


@register
class Garces2023(RolloutPolicy):
    """Garces et al. (2023): IA base, standard CE, whole-map sampling, previous-hour demand; planned exactly."""

    name = "garces2023"
    defaults: ClassVar[dict[str, Any]] = {"forecast": "previous-hour", "horizon": 10, "samples": 1000, "base": "ia", "scope": "map", "ce": "standard",
                                          **EXACT}


def pinned_options(label: str, values: dict[str, Any] = PAPER) -> dict[str, Any]:
    """Those of ``values`` that ``label`` (``"surge:cap=12"``) does not set itself and ``surge`` does not default to, for a ``surge`` label; none for any other.

    Added to a label's options, the default :data:`PAPER` make it plan as
    the paper does (``surge:base=ia`` then varies the paper's method),
    whatever ``surge``'s defaults are now.
    """
    name, options = split_policy(label)
    if name != Surge.name:
        return {}
    return {k: v for k, v in values.items() if k not in options and Surge.defaults.get(k) != v}
