"""The demand-world interface: who wants a taxi, where and when, for a whole year (paper §3 and §4.2).

A :class:`DemandWorld` holds one year of demand on a :class:`~city.graph.City`:
venues and events with their text, hourly weather, points of interest (the
locale counts n_λ(j) of the demand-assignment module) and, per sector and
hour, the expected number of requests λ and a realised count η.  From it a
caller draws the trip-level requests of any hour: pickup intersection ρ,
drop-off intersection δ and entry minute.

Intersections are drawn with the occupancy-weighted assignment of the design
(O(j, h) = Σ_λ n_λ(j)·p_λ(h)·o_λ normalised within the sector) unless the
world fixes them (an event's arrivals end at its venue, its departures start
there).  Requests of an hour come from their own random stream, seeded by
(world seed, year, day, hour), so they do not depend on which hours were drawn
before.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

import numpy as np

from city.demand.dates import HOLIDAY_COUNTRY, holiday_dates
from city.errors import ConfigError
from city.graph import City
from city.io.events import Event, Venue
from city.io.occupancy import day_type, occupancy, sector_distribution
from city.io.poi import Pois
from city.io.weather import HourlyWeather, hours_in_year
from city.sim import Requests


@dataclass(frozen=True)
class HourTrips:
    """The requests of one hour before their free intersections are drawn.

    ``pickup_node`` / ``dropoff_node`` hold an intersection the world fixes
    (an event venue) or -1 where the intersection is drawn from the sector's
    assignment distribution.
    """

    pickup_sector: np.ndarray
    dropoff_sector: np.ndarray
    minute: np.ndarray
    pickup_node: np.ndarray
    dropoff_node: np.ndarray

    @staticmethod
    def free(pickup_sector: np.ndarray, dropoff_sector: np.ndarray, minute: np.ndarray) -> "HourTrips":
        """Trips whose intersections are all drawn."""
        none = np.full(len(pickup_sector), -1, dtype=np.int64)
        return HourTrips(np.asarray(pickup_sector), np.asarray(dropoff_sector), np.asarray(minute), none, none)


class DemandWorld:
    """One year of demand on a city; see the module docstring.

    Attributes
    ----------
    city : City
    year, seed : int
    venues : list of Venue
    events : list of Event
        Sorted by start time.
    weather : HourlyWeather
    locale_counts : ndarray, shape (n_nodes, 4)
        n_λ(j) for the locale types of :data:`city.io.occupancy.LOCALE_TYPES`.
    pois : Pois or None
        The points of interest behind ``locale_counts``.
    notes : list of str
        Choices made for the inputs (synthesised restaurants, synthetic weather …).
    holidays : frozenset of date
        The year's public holidays (a scenario's ``[holidays]``; US federal by default). They run on
        a Sunday profile, and the predictor's holiday flag reads them.
    schedules : dict or None
        Occupancy schedules of a scenario's ``[occupancy]`` file, in the shape of
        :data:`city.io.occupancy.SCHEDULES`; ``None`` for the built-in ones.
    """

    def __init__(
        self,
        city: City,
        year: int,
        seed: int,
        venues: list[Venue],
        events: list[Event],
        weather: HourlyWeather,
        locale_counts: np.ndarray,
        pois: Pois | None,
        notes: list[str],
        *,
        holidays: tuple[str, str | None] = (HOLIDAY_COUNTRY, None),
        schedules: dict | None = None,
    ) -> None:
        if weather.year != year or len(weather.temp_f) != hours_in_year(year):
            raise ConfigError(f"weather covers {weather.year} with {len(weather.temp_f)} hours; the world needs {year} ({hours_in_year(year)} hours)")
        self.city = city
        self.year = int(year)
        self.seed = int(seed)
        self.venues = list(venues)
        self.events = sorted(events, key=lambda e: (e.start, e.event_id))
        self.weather = weather
        self.locale_counts = np.asarray(locale_counts, dtype=np.float64)
        self.pois = pois
        self.notes = notes
        self.holidays = holiday_dates(self.year, *holidays)
        self.schedules = schedules
        self.n_hours = hours_in_year(year)
        self._eligible = np.asarray(city.pickup, dtype=bool)
        # Eligible nodes grouped by sector, for drawing intersections by inverse CDF.
        self._node_order = np.flatnonzero(self._eligible)[np.argsort(city.node_sector[self._eligible], kind="stable")]
        bounds = np.searchsorted(city.node_sector[self._node_order], np.arange(city.n_sectors + 1))
        self._lo, self._hi = bounds[:-1], bounds[1:]
        self._dist_cache: dict[tuple[str, int], tuple[np.ndarray, np.ndarray]] = {}
        self._active: list[list[int]] | None = None

    # ------------------------------------------------------------ time
    def hour_index(self, when: dt.datetime) -> int:
        """Row of ``when``'s hour in the year's arrays: ``(day_of_year - 1) * 24 + hour``."""
        if when.year != self.year:
            raise ConfigError(f"{when:%Y-%m-%d %H:%M} is outside the demand world's year {self.year}")
        return (when.timetuple().tm_yday - 1) * 24 + when.hour

    def _start(self, date: dt.date, hour: int) -> int:
        if not 0 <= hour < 24:
            raise ConfigError(f"hour must be 0..23, got {hour}")
        return self.hour_index(dt.datetime.combine(date, dt.time(hour)))

    def when(self, hour_index: int) -> dt.datetime:
        """The start of the hour at row ``hour_index``."""
        return dt.datetime(self.year, 1, 1) + dt.timedelta(hours=int(hour_index))

    # ------------------------------------------------------------ demand (per world)
    def expected_rate(self) -> np.ndarray:
        """``(hours_in_year, S)`` expected requests per sector-hour: the ground-truth λ."""
        raise NotImplementedError

    def hourly_counts(self) -> np.ndarray:
        """``(hours_in_year, S)`` realised request counts per sector-hour."""
        raise NotImplementedError

    def od_matrix(self, when: dt.datetime) -> np.ndarray:
        """β for the hour of ``when``: ``(S, S)``, row = pickup sector, rows sum to one."""
        raise NotImplementedError

    def beta_from_months(self, months: tuple[int, ...]) -> np.ndarray:
        """β ``(S, S)`` from the hours of ``months`` only; see :func:`city.demand.estimate_beta`."""
        raise NotImplementedError

    def _hour_trips(self, h: int, rng: np.random.Generator) -> HourTrips:
        """Every request of hour ``h``: sectors, entry minutes and any intersections fixed by the world."""
        raise NotImplementedError

    # ------------------------------------------------------------ assignment
    def _assignment(self, when: dt.datetime) -> tuple[np.ndarray, np.ndarray]:
        """O(j, h) normalised within sectors, and its cumulative sum over ``_node_order``."""
        key = (day_type(when.date()), when.hour)
        if key not in self._dist_cache:
            weights = occupancy(self.locale_counts, when.hour, key[0], self.schedules)
            p = sector_distribution(weights, self.city.node_sector, self.city.n_sectors, self._eligible)
            self._dist_cache[key] = (p, np.cumsum(p[self._node_order]))
        return self._dist_cache[key]

    def pickup_dist(self, when: dt.datetime) -> np.ndarray:
        """ρ: ``(n_nodes,)`` occupancy-weighted probabilities, summing to one within each sector."""
        return self._assignment(when)[0].copy()

    def dropoff_dist(self, when: dt.datetime) -> np.ndarray:
        """δ: ``(n_nodes,)`` occupancy-weighted probabilities, summing to one within each sector.

        Drop-offs go where people are expected, as pickups come from there; the
        paper uses one assignment for both.
        """
        return self._assignment(when)[0].copy()

    def _draw_nodes(self, when: dt.datetime, sectors: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """One intersection per entry of ``sectors``, drawn from the sector's assignment distribution."""
        _, cum = self._assignment(when)
        lo, hi = self._lo[sectors], self._hi[sectors]
        base = np.where(lo > 0, cum[np.maximum(lo - 1, 0)], 0.0)
        top = cum[hi - 1]
        pos = np.searchsorted(cum, base + rng.random(len(sectors)) * (top - base), side="right")
        return self._node_order[np.clip(pos, lo, hi - 1)]

    # ------------------------------------------------------------ requests
    def requests(self, date: dt.date, hour: int, minutes: int = 60) -> Requests:
        """Trip-level requests from ``date`` ``hour``:00 for ``minutes`` minutes.

        Entry minutes count from the start (0 … minutes-1).  Each hour is drawn
        whole from its own random stream and cut at ``minutes``, so a shorter
        window is a prefix of a longer one, and for every whole hour the
        pickups per sector equal :meth:`hourly_counts` exactly.

        Raises
        ------
        ConfigError
            A date or hour outside the world's year, or ``minutes < 1``.
        """
        if minutes < 1:
            raise ConfigError(f"minutes must be at least 1, got {minutes}")
        h0 = self._start(date, hour)
        n_h = -(-minutes // 60)
        if h0 + n_h > self.n_hours:
            raise ConfigError(f"{minutes} minutes from {date} {hour}:00 run past the end of {self.year}")
        parts = []
        for k in range(n_h):
            h = h0 + k
            when = self.when(h)
            rng = np.random.default_rng([self.seed, self.year, when.timetuple().tm_yday, when.hour])
            trips = self._hour_trips(h, rng)
            pick = np.where(trips.pickup_node >= 0, trips.pickup_node, self._draw_nodes(when, trips.pickup_sector, rng))
            drop = np.where(trips.dropoff_node >= 0, trips.dropoff_node, self._draw_nodes(when, trips.dropoff_sector, rng))
            entry = trips.minute + 60 * k
            keep = entry < minutes
            parts.append((pick[keep], drop[keep], entry[keep]))
        return Requests.sorted(*(np.concatenate(x) for x in zip(*parts)))

    # ------------------------------------------------------------ events
    def events_active(self, when: dt.datetime) -> list[Event]:
        """Events overlapping the hour that contains ``when``."""
        h = self.hour_index(when)
        if self._active is None:
            self._active = [[] for _ in range(self.n_hours)]
            origin = dt.datetime(self.year, 1, 1)
            for i, ev in enumerate(self.events):
                first = max(0, int((ev.start - origin).total_seconds() // 3600))
                last = min(self.n_hours, int(-(-(ev.end - origin).total_seconds() // 3600)))
                for k in range(first, last):
                    self._active[k].append(i)
        return [self.events[i] for i in self._active[h]]

    def event_titles_by_sector(self, when: dt.datetime) -> list[list[str]]:
        """Per sector, the titles of the events active that hour in the sector or an adjacent one."""
        out: list[list[str]] = [[] for _ in range(self.city.n_sectors)]
        for ev in self.events_active(when):
            for s in self.city.local_sectors(ev.sector):
                out[s].append(ev.title)
        return out



def check_seed_year(seed: int, year: int) -> None:
    if seed < 0:
        raise ConfigError(f"seed must be non-negative, got {seed}")
    if not 1900 < year < 2200:
        raise ConfigError(f"year must be a calendar year, got {year}")


def surge_report(world: DemandWorld, date: dt.date, hour: int) -> list[dict]:
    """Per sector: expected requests (pickups) at ``date`` ``hour``, the usual level and the ratio.

    ``usual`` is the median expected demand of the same weekday and hour over
    the year; ``dropoffs`` / ``usual_dropoffs`` the same for the trips that
    end in the sector (an event's arrivals end at its venue).  Rows are sorted
    by ``ratio``, highest first, and list the events behind the sector's
    demand that hour.
    """
    h = world._start(date, hour)
    rate = world.expected_rate()
    first = (date.weekday() - dt.date(world.year, 1, 1).weekday()) % 7
    same = np.arange(first * 24 + hour, world.n_hours, 7 * 24)
    usual = np.median(rate[same], axis=0)
    expected = rate[h]

    def dropoffs(row: int) -> np.ndarray:
        return rate[row] @ world.od_matrix(world.when(int(row)))

    drop = dropoffs(h)
    usual_drop = np.median([dropoffs(r) for r in same], axis=0)
    ratio = expected / np.maximum(usual, 1e-9)
    titles = world.event_titles_by_sector(world.when(h))
    rows = [
        {
            "sector": s,
            "name": world.city.sector_names[s],
            "expected": float(expected[s]),
            "usual": float(usual[s]),
            "ratio": float(ratio[s]),
            "dropoffs": float(drop[s]),
            "usual_dropoffs": float(usual_drop[s]),
            "events": titles[s],
        }
        for s in range(world.city.n_sectors)
    ]
    return sorted(rows, key=lambda r: -r["ratio"])
