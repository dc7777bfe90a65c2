"""The demand world: who wants a taxi, where and when, for a whole year (paper §3 and §4.2).

Modules, each importing only those above it:

``dates``       the evaluation evening and the holidays (``holidays`` package)
``world``       :class:`DemandWorld`, the interface every world offers, and :func:`surge_report`
``climate``     synthetic hourly weather and its effect on demand
``geography``   anchor sectors, busyness, points of interest, sector intensity, gravity OD
``venues``      venues and their calendar of :class:`~city.demand.venues.EventSpec`
``profile``     the base profile from real trip data, and the fleet's share of the market
``real_level``  base demand at a city's real hourly trip totals, split over sectors
``attendance``  event text written before the event, realised attendance, taxi trips
``synthetic``   :class:`SyntheticWorld`: base demand plus event surges, on any map
``recorded``    :class:`RecordedWorld`: real trip records replayed
``level_check``, ``split_check``  the ``nyc`` world's level and split against real counts (scripts)

:func:`estimate_beta` gives β from chosen months only (the training months).
"""

from __future__ import annotations

import numpy as np

from city.demand.climate import synthetic_weather, weather_factor
from city.demand.dates import EVAL_DATE, evaluation_date, holiday_dates
from city.demand.geography import find_anchors, gravity_od, synthetic_pois
from city.demand.profile import FLEET_SHARE, PROFILE, REF_RATE
from city.demand.recorded import RecordedWorld
from city.demand.synthetic import SyntheticWorld, synthetic_world
from city.demand.world import DemandWorld, HourTrips, surge_report
from city.errors import ConfigError


def estimate_beta(world: DemandWorld, months: tuple[int, ...] | range) -> np.ndarray:
    """β ``(S, S)`` from the months ``months`` only (1 = January): recorded trips, or the world's expected flows.

    Use the training months, so that no β a model is judged with comes from its test months.
    """
    months = tuple(int(m) for m in months)
    if not months or any(not 1 <= m <= 12 for m in months):
        raise ConfigError(f"months must be 1..12, got {months}")
    return world.beta_from_months(months)


__all__ = [
    "EVAL_DATE",
    "FLEET_SHARE",
    "PROFILE",
    "REF_RATE",
    "DemandWorld",
    "HourTrips",
    "RecordedWorld",
    "SyntheticWorld",
    "estimate_beta",
    "evaluation_date",
    "find_anchors",
    "gravity_od",
    "holiday_dates",
    "surge_report",
    "synthetic_pois",
    "synthetic_weather",
    "synthetic_world",
    "weather_factor",
]
