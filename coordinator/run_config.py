"""What one distributed run is: its settings, and the instance and policy they make.

The coordinator, the launchers, the checkpoint and the watcher all build a
run from a :class:`FleetConfig`, so a distributed run and its in-process
reference are the same instance.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agents.base import EpisodeContext, Policy, make_policy, policy_class
from agents.rollout import RolloutConfig
from agents.rollout_policy import RolloutPolicy
from city.errors import ConfigError
from city.graph import City
from city.sim import Requests


@dataclass(frozen=True)
class FleetConfig:
    """One distributed episode: the same instance as ``surge evaluate``'s (date, hour, seed)."""

    run: str = "demo"
    scenario: str = "synthetic"
    data_dir: str | None = None
    date: str = "2022-11-17"
    hour: int = 19
    minutes: int = 60
    taxis: int = 8
    seed: int = 0
    world_seed: int = 0
    policy: str = "surge"
    options: dict = field(default_factory=dict)
    deadline_s: float = 30.0
    join_timeout_s: float = 120.0
    #: Least wall time per simulated minute: 0 runs as fast as the agents plan, 60 in real time.
    minute_s: float = 0.0
    #: Ask a ``surge predictor serve`` process on the bus for each hour's forecast instead of computing it here.
    predictor: bool = False
    #: Seconds the clock waits for the agents of a partition to come back before the run ends.
    partition_timeout_s: float = 120.0
    #: Seconds the launcher's agents wait for a vanished coordinator (to be resumed) before they leave.
    grace_s: float = 30.0

    def instance(self) -> tuple[Any, Requests, np.ndarray, EpisodeContext]:
        """The scenario, requests, start positions and episode context of this run: one place for both runs that must agree."""
        from city.episode import episode_requests, initial_positions
        from city.scenario import load_scenario

        date = dt.date.fromisoformat(self.date)
        scen = load_scenario(self.scenario, self.data_dir, year=date.year, seed=self.world_seed)
        context = EpisodeContext(city=scen.city, date=date, hour=self.hour, minutes=self.minutes, seed=self.seed, world=scen.world)
        return scen, episode_requests(scen.world, date, self.hour, self.minutes), initial_positions(scen.city, self.taxis, self.seed), context

    def policy_class(self) -> type[Policy]:
        cls = policy_class(self.policy)
        if not (issubclass(cls, RolloutPolicy) or cls.central):
            raise ConfigError(f"policy {self.policy!r}: the distributed runtime runs rollout policies (surge, garces2023) "
                              "and centrally computed ones (match, rebalance)")
        if cls.central and self.predictor:
            raise ConfigError(f"policy {self.policy!r} is computed by the coordinator, which reads its own forecast: "
                              "a predictor service serves rollout agents only")
        return cls

    def forecast_name(self) -> str:
        """The forecast provider the run uses: the ``forecast`` option, or the policy's default."""
        return str(self.options.get("forecast") or getattr(self.policy_class(), "defaults", {}).get("forecast"))

    def make_policy(self, city: City) -> Policy:
        """The in-process policy: the reference, and the forecast source when there is no predictor service."""
        self.policy_class()
        return make_policy(self.policy, city, **self.options)  # type: ignore[return-value]

    def rollout_config(self) -> RolloutConfig:
        """The planner settings alone, without loading a forecast (the predictor service has it)."""
        cls = self.policy_class()
        if not issubclass(cls, RolloutPolicy):
            return RolloutConfig()  # a central policy: the agents plan nothing with it
        planner = {k: v for k, v in self.options.items() if k not in ("forecast", "model")}
        try:
            return cls.rollout_config(**planner)
        except TypeError as exc:
            raise ConfigError(f"policy {self.policy!r}: {exc}") from None
