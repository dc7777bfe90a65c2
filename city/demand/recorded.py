"""A demand world replayed from real trip records (:class:`city.io.trips.TripTable`)."""

from __future__ import annotations

import datetime as dt
from typing import TYPE_CHECKING

import numpy as np

from city.demand.climate import synthetic_weather
from city.demand.dates import HOLIDAY_COUNTRY
from city.demand.geography import find_anchors, locale_counts
from city.demand.world import DemandWorld, HourTrips, check_seed_year
from city.errors import ConfigError
from city.graph import City
from city.io.events import Event, Venue
from city.io.poi import Pois
from city.io.weather import HourlyWeather

if TYPE_CHECKING:
    from city.io.trips import TripTable


class RecordedWorld(DemandWorld):
    """Demand replayed from real trip records.

    ``hourly_counts`` are the records' pickups per sector-hour and
    ``expected_rate`` the same counts as floats (for recorded data the truth
    is what happened).  β is the records' drop-off frequency per pickup
    sector; ``requests`` are the real trips of the hour, with entry minutes
    from the records and intersections drawn by ρ and δ.  Events, venues,
    weather and points of interest are passed in; without weather the world
    uses seeded synthetic weather, without points of interest synthetic ones
    placed by the records' pickup density.

    Raises
    ------
    ConfigError
        Records in a sector that has no pickup-eligible intersection.
    """

    def __init__(
        self,
        city: City,
        trips: TripTable,
        *,
        year: int = 2022,
        seed: int = 0,
        events: list[Event] | tuple[Event, ...] = (),
        venues: list[Venue] | tuple[Venue, ...] = (),
        weather: HourlyWeather | None = None,
        pois: Pois | None = None,
        holidays: tuple[str, str | None] = (HOLIDAY_COUNTRY, None),
        schedules: dict | None = None,
    ) -> None:
        from city.io.trips import hourly_counts, od_matrix

        check_seed_year(seed, year)
        notes: list[str] = []
        if weather is None:
            weather = synthetic_weather(year, seed)
            notes.append(f"weather: {weather.source}")
        S = city.n_sectors
        counts = hourly_counts(trips, year, S)
        empty = np.bincount(city.node_sector[city.pickup], minlength=S) == 0
        used = (counts.sum(axis=0) > 0) | (np.bincount(trips.dropoff_sector, minlength=S)[:S] > 0)
        if np.any(empty & used):
            bad = ", ".join(city.sector_names[s] for s in np.flatnonzero(empty & used))
            raise ConfigError(f"trip records use sectors with no pickup-eligible intersection: {bad}")
        busy = counts.sum(axis=0).astype(np.float64)
        busy = busy / busy.mean() if busy.sum() > 0 else np.ones(S)
        anchors = find_anchors(city)
        locale, pois = locale_counts(city, pois, busy, anchors, np.random.default_rng([seed, 12]), notes)
        super().__init__(city, year, seed, list(venues), list(events), weather, locale, pois, notes, holidays=holidays, schedules=schedules)

        self._counts = counts
        self._counts.setflags(write=False)
        self._rate = counts.astype(np.float64)
        self._rate.setflags(write=False)
        self._beta = od_matrix(trips, S)
        self._trips = trips
        start = np.datetime64(dt.datetime(year, 1, 1), "m")
        minute = (trips.request_time.astype("datetime64[m]") - start).astype(np.int64)
        keep = (minute >= 0) & (minute < self.n_hours * 60)
        order = np.argsort(minute[keep], kind="stable")
        self._minute = minute[keep][order]
        self._pu = np.asarray(trips.pickup_sector)[keep][order]
        self._do = np.asarray(trips.dropoff_sector)[keep][order]

    def expected_rate(self) -> np.ndarray:
        return self._rate

    def hourly_counts(self) -> np.ndarray:
        return self._counts

    def od_matrix(self, when: dt.datetime) -> np.ndarray:
        """β from the records' origin–destination frequencies (the same for every hour)."""
        self.hour_index(when)  # rejects a time outside the year, like the synthetic world
        return self._beta.copy()

    def _hour_trips(self, h: int, rng: np.random.Generator) -> HourTrips:
        lo, hi = np.searchsorted(self._minute, [60 * h, 60 * h + 60])
        return HourTrips.free(self._pu[lo:hi], self._do[lo:hi], self._minute[lo:hi] - 60 * h)

    def beta_from_months(self, months: tuple[int, ...]) -> np.ndarray:
        """β from the records of ``months`` only (e.g. the training months)."""
        from city.io.trips import od_matrix

        return od_matrix(self._trips, self.city.n_sectors, months=months)
