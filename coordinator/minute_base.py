"""The minute's base controls that the coordinator computes once for every taxi, and the ``rebalance`` base's targets."""

from __future__ import annotations

import numpy as np

from agents.base import Policy, busy_next_hops
from agents.rollout import HourInputs, base_controls
from agents.rollout_config import RolloutConfig
from city.forecast import Forecast
from city.graph import City
from city.sim import Observation


class MinuteBase:
    """Base controls and targets of a minute, computed once a minute (the hour's forecast reading once an hour).

    A snapshot asked for during the minute gets the same arrays as the minute's state.  ``central``
    is a central policy (its joint control is the base), ``None`` for a rollout.
    """

    def __init__(self, city: City, rollout: RolloutConfig, central: Policy | None) -> None:
        self.city, self.rollout, self.central = city, rollout, central
        self._minute: tuple[int, np.ndarray, np.ndarray] | None = None
        self._hour: tuple[int, HourInputs] | None = None

    def of(self, obs: Observation, hour_forecast: tuple[int, Forecast] | None) -> tuple[np.ndarray, np.ndarray]:
        """The minute's base controls and the ``rebalance`` base's targets (empty for the other bases).

        Before the run's first forecast (a snapshot asked for while the taxis join) the ``rebalance``
        base has no targets yet: every free taxi stays, and the first minute's full state replaces it.
        """
        if self._minute is not None and self._minute[0] == obs.t:
            return self._minute[1], self._minute[2]
        rebalancing = self.central is None and self.rollout.base == "rebalance"
        if rebalancing and (hour_forecast is None or hour_forecast[0] != obs.t // 60):
            return busy_next_hops(self.city, obs).astype(np.int32), np.full(obs.pos.size, -1, dtype=np.int32)
        if self.central is not None:
            base, home = np.asarray(self.central.act(obs), dtype=np.int32), np.empty(0, dtype=np.int32)
        else:
            base, home = base_controls(self.city, self.rollout, obs, self._hour_inputs(hour_forecast) if rebalancing else None)
        self._minute = (int(obs.t), base, home)
        return base, home

    def _hour_inputs(self, hour_forecast: tuple[int, Forecast]) -> HourInputs:
        hour, forecast = hour_forecast
        if self._hour is None or self._hour[0] != hour:
            self._hour = (hour, HourInputs.of(self.city, forecast))
        return self._hour[1]
