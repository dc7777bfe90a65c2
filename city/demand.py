"""The demand world: who wants a taxi, where and when, for a whole year (paper §3 and §4.2).

A :class:`DemandWorld` holds one year of demand on a :class:`~city.graph.City`:
venues and events with their text, hourly weather, points of interest (the
locale counts n_λ(j) of the demand-assignment module) and, per sector and
hour, the expected number of requests λ and a realised count η.  From it a
caller draws the trip-level requests of any hour: pickup intersection ρ,
drop-off intersection δ and entry minute.

Two worlds share that interface:

* :class:`SyntheticWorld` generates everything from a seed, on the embedded
  synthetic map or on a real one: base demand per sector × hour × weekday ×
  month × weather, plus event surges before each start and after each end
  whose size (attendance × taxi share) the event text carries.
* :class:`RecordedWorld` replays real trip records (:class:`city.trips.TripTable`).

Intersections are drawn with the occupancy-weighted assignment of the design
(O(j, h) = Σ_λ n_λ(j)·p_λ(h)·o_λ normalised within the sector), drop-off
sectors with the origin–destination matrix β.  Requests of an hour come from
their own random stream, seeded by (world seed, year, day, hour), so they do
not depend on which hours were drawn before.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import itertools
import random
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.special import gammainc

from city import texts
from city.errors import ConfigError
from city.events import Event, Venue
from city.graph import City
from city.occupancy import LOCALE_TYPES, day_type, occupancy, sector_distribution
from city.poi import Pois, locale_counts_from_pois
from city.sim import Requests
from city.weather import HourlyWeather, hours_in_year

if TYPE_CHECKING:
    from city.trips import TripTable

#: The paper's evaluation date: a Thursday with Broadway and arena events and an event surge at 7 pm.
EVAL_DATE = dt.date(2022, 11, 17)

#: Citywide base requests per hour (no events) at the reference point: a weekday at 19:00, dry
#: weather, month factor 1.  Event surges come on top: on a typical weekday they lift the citywide
#: total to ≈ 250 / 350 / 440 / 330 requests at 15 / 17 / 19 / 21 h, so that 100 taxis on the
#: ≈2,200-node synthetic map are stressed but not swamped.
REF_RATE = 290.0

# Base profile of the citywide demand by hour, relative to a weekday 19:00.  The evening is flat:
# its peak comes from the events (concerts, talks, games, shows) that start and end then.
# fmt: off
PROFILES: dict[str, np.ndarray] = {
    "weekday":  np.array([.43, .29, .20, .16, .16, .23, .46, .75, .93, .87, .78, .81,
                          .87, .87, .90, .87, .88, .78, .98, .86, 1.04, .98, .80, .60]),
    "saturday": np.array([.80, .65, .51, .36, .26, .17, .20, .29, .41, .55, .72, .87,
                          .96, .99, .99, .99, .92, .96, 1.08, 1.05, 1.13, 1.08, .98, .87]),
    "sunday":   np.array([.90, .72, .58, .41, .26, .17, .17, .23, .32, .46, .64, .80,
                          .87, .90, .90, .90, .81, .79, .81, .74, .71, .62, .49, .37]),
}
#: Friday nights run later than other weeknights (multiplier on the weekday profile).
FRIDAY_NIGHT = np.array([1.0] * 17 + [1.04, 1.07, 1.10, 1.15, 1.22, 1.32, 1.40])
#: Evening (+) versus morning (−) weight by hour; a sector's tilt scales it (nightlife versus offices).
TILT = np.array([.8, .6, .3, 0, 0, 0, -.4, -1, -1, -1, -.6, -.3,
                 -.2, -.2, -.2, -.1, .2, .5, .8, 1, 1, 1, 1, 1])
# fmt: on
DAY_FACTOR = (0.95, 0.98, 1.0, 1.0, 1.03, 1.0, 1.0)
MONTH_FACTOR = (0.88, 0.90, 0.96, 0.98, 1.0, 0.99, 0.94, 0.92, 0.99, 1.02, 1.0, 1.03)

#: Taxi trips of the simulated fleet per attendee, arriving and departing, by category.
#: Sized so that a mid-size event (about 1,000 people) doubles or triples its sector's evening demand.
TAXI_SHARE: dict[str, tuple[float, float]] = {
    "conferences": (0.020, 0.024),
    "expos": (0.006, 0.008),
    "concerts": (0.020, 0.022),
    "festivals": (0.002, 0.0025),
    "performing-arts": (0.0030, 0.0040),
    "community": (0.020, 0.020),
    "sports": (0.0050, 0.0065),
}
#: Share of arrival pickups in the venue's own sector (the rest in adjacent sectors); departures likewise.
#: Most arrivals are picked up at the venue's block (drop-offs nearby, short hops from around the corner).
ARRIVAL_HOME_SHARE = 0.9
DEPARTURE_HOME_SHARE = 0.9
#: Events longer than this (minutes) spread part of their arrivals and departures over their duration.
LONG_EVENT_MIN = 300
#: Target mean trip length of the gravity OD matrix, in hops.
TARGET_TRIP_HOPS = 15.0
#: Locale counts added to every intersection so that each can be drawn at any hour.
LOCALE_FLOOR = 0.05
#: POI radius for locale counts: metres, or degrees on lon/lat maps (≈100 m in Manhattan).
POI_RADIUS = {"m": 100.0, "lonlat": 0.0012}


def evaluation_date(year: int) -> dt.date:
    """The world's surge evening: the third Thursday of November (2022-11-17 for 2022)."""
    nov1 = dt.date(year, 11, 1)
    return nov1 + dt.timedelta(days=(3 - nov1.weekday()) % 7 + 14)


def holidays(year: int) -> set[dt.date]:
    """Days that follow a Sunday profile: New Year, Memorial Day, July 4, Labor Day, Thanksgiving, Christmas."""
    may31 = dt.date(year, 5, 31)
    sep1 = dt.date(year, 9, 1)
    nov1 = dt.date(year, 11, 1)
    return {
        dt.date(year, 1, 1),
        may31 - dt.timedelta(days=may31.weekday()),
        dt.date(year, 7, 4),
        sep1 + dt.timedelta(days=(7 - sep1.weekday()) % 7),
        nov1 + dt.timedelta(days=(3 - nov1.weekday()) % 7 + 21),
        dt.date(year, 12, 25),
    }


# ====================================================================== base class
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
        n_λ(j) for the locale types of :data:`city.occupancy.LOCALE_TYPES`.
    pois : Pois or None
        The points of interest behind ``locale_counts``.
    notes : list of str
        Choices made for the inputs (synthesised restaurants, synthetic weather …).
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

    def _hour_trips(self, h: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pickup sector, drop-off sector and entry minute (0..59) of every request of hour ``h``."""
        raise NotImplementedError

    # ------------------------------------------------------------ assignment
    def _assignment(self, when: dt.datetime) -> tuple[np.ndarray, np.ndarray]:
        """O(j, h) normalised within sectors, and its cumulative sum over ``_node_order``."""
        key = (day_type(when.date()), when.hour)
        if key not in self._dist_cache:
            weights = occupancy(self.locale_counts, when.hour, key[0])
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
            ps, ds, minute = self._hour_trips(h, rng)
            pick = self._draw_nodes(when, ps, rng)
            drop = self._draw_nodes(when, ds, rng)
            entry = minute + 60 * k
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


# ====================================================================== synthetic world
class SyntheticWorld(DemandWorld):
    """A seeded synthetic year of demand on any map; build it with :func:`synthetic_world`.

    Extra attributes: ``anchors`` (sector of the theatre district, arena,
    convention centre and festival park), ``intensity`` (each sector's share
    of base demand) and ``demand_scale``.
    """

    def __init__(
        self,
        city: City,
        year: int = 2022,
        seed: int = 0,
        weather: HourlyWeather | None = None,
        pois: Pois | None = None,
        demand_scale: float = 1.0,
    ) -> None:
        _check_seed_year(seed, year)
        if not demand_scale > 0:
            raise ConfigError(f"demand_scale must be positive, got {demand_scale}")
        notes: list[str] = []
        if weather is None:
            weather = synthetic_weather(year, seed)
            notes.append(f"weather: {weather.source}")
        self.anchors = find_anchors(city)
        busy = _busyness(city, self.anchors, np.random.default_rng([seed, 11]))
        counts, pois = _locale_counts(city, pois, busy, self.anchors, np.random.default_rng([seed, 12]), notes)
        self.intensity, tilt = _intensity(city, busy, counts, self.anchors)
        self.demand_scale = float(demand_scale)
        venues = _venues(city, self.anchors, busy, np.random.default_rng([seed, 13]))
        specs = _schedule(venues, year, np.random.default_rng([seed, 14]))
        events, attendance = _events(specs, venues, random.Random(f"surge-texts-{seed}"))
        super().__init__(city, year, seed, venues, events, weather, counts, pois, notes)

        self._base = _base_rate(city, year, weather, self.intensity, tilt) * self.demand_scale
        self._surge_split = _surge_split(city, self.intensity)
        self._arrivals, self._departures, self._event_rows = _surges(self.events, attendance, year, city.n_sectors, self.demand_scale)
        arr_split, dep_split = self._surge_split
        self._rate = self._base + self._arrivals @ arr_split + self._departures @ dep_split
        self._rate.setflags(write=False)
        self._beta = gravity_od(city, self.intensity)
        self._counts: np.ndarray | None = None

    def base_rate(self) -> np.ndarray:
        """``(hours_in_year, S)`` expected requests without event surges."""
        return self._base

    def expected_rate(self) -> np.ndarray:
        return self._rate

    def hourly_counts(self) -> np.ndarray:
        """Poisson draws of :meth:`expected_rate`, from the world seed (computed once)."""
        if self._counts is None:
            counts = np.random.default_rng([self.seed, self.year, 15]).poisson(self._rate)
            counts.setflags(write=False)
            self._counts = counts
        return self._counts

    def od_matrix(self, when: dt.datetime) -> np.ndarray:
        """β of the hour: gravity trips mixed with arrival trips that head for event venues."""
        h = self.hour_index(when)
        arr_split = self._surge_split[0]
        to_venue = arr_split.T * self._arrivals[h][None, :]  # [pickup sector, venue sector]
        total = self._rate[h]
        other = np.maximum(total - to_venue.sum(axis=1), 0.0)
        flow = other[:, None] * self._beta + to_venue
        rows = flow.sum(axis=1, keepdims=True)
        return np.where(rows > 0, flow / np.where(rows > 0, rows, 1.0), self._beta)

    def _hour_trips(self, h: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        counts = self.hourly_counts()[h]
        ps = np.repeat(np.arange(self.city.n_sectors), counts)
        cum = np.cumsum(self.od_matrix(self.when(h)), axis=1)
        u = rng.random(len(ps)) * cum[ps, -1]
        ds = np.minimum((cum[ps] <= u[:, None]).sum(axis=1), self.city.n_sectors - 1)
        minute = rng.integers(0, 60, size=len(ps))
        return ps, ds, minute

    def event_titles_by_sector(self, when: dt.datetime) -> list[list[str]]:
        """Per sector, titles of the events whose arrivals or departures add at least half a trip that hour."""
        h = self.hour_index(when)
        ev, hours, trips_arr, trips_dep = self._event_rows
        lo, hi = np.searchsorted(hours, [h, h + 1])
        arr_split, dep_split = self._surge_split
        share = {}
        for i in range(lo, hi):
            e = self.events[ev[i]]
            add = trips_arr[i] * arr_split[e.sector] + trips_dep[i] * dep_split[e.sector]
            for s in np.flatnonzero(add >= 0.5):
                share.setdefault(int(s), []).append((-add[s], e.title))
        return [[t for _, t in sorted(share.get(s, []))] for s in range(self.city.n_sectors)]


def synthetic_world(
    city: City,
    year: int = 2022,
    seed: int = 0,
    weather: HourlyWeather | None = None,
    pois: Pois | None = None,
    demand_scale: float = 1.0,
) -> SyntheticWorld:
    """Generate a year of demand on ``city``; the same arguments always give the same world.

    Parameters
    ----------
    city : City
        The synthetic map or a real one.  Anchors for the theatre district,
        arena, convention centre and festival park come from
        ``city.info["anchors"]`` or, on a real map, from sector names (see
        :func:`find_anchors`).
    year, seed : int
    weather : HourlyWeather, optional
        Real hourly weather for ``year``; seeded synthetic weather otherwise.
    pois : Pois, optional
        Real points of interest in the city's coordinates; synthetic ones otherwise.
    demand_scale : float
        Multiplies all demand (base and surges); 1.0 is calibrated for 100 taxis.
    """
    return SyntheticWorld(city, year=year, seed=seed, weather=weather, pois=pois, demand_scale=demand_scale)


# ====================================================================== recorded world
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
    ) -> None:
        from city.trips import hourly_counts, od_matrix

        _check_seed_year(seed, year)
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
        locale, pois = _locale_counts(city, pois, busy, anchors, np.random.default_rng([seed, 12]), notes)
        super().__init__(city, year, seed, list(venues), list(events), weather, locale, pois, notes)

        self._counts = counts
        self._counts.setflags(write=False)
        self._rate = counts.astype(np.float64)
        self._rate.setflags(write=False)
        self._beta = od_matrix(trips, S)
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

    def _hour_trips(self, h: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        lo, hi = np.searchsorted(self._minute, [60 * h, 60 * h + 60])
        return self._pu[lo:hi], self._do[lo:hi], self._minute[lo:hi] - 60 * h


def _check_seed_year(seed: int, year: int) -> None:
    if seed < 0:
        raise ConfigError(f"seed must be non-negative, got {seed}")
    if not 1900 < year < 2200:
        raise ConfigError(f"year must be a calendar year, got {year}")


# ====================================================================== report
def surge_report(world: DemandWorld, date: dt.date, hour: int) -> list[dict]:
    """Per sector: expected requests at ``date`` ``hour``, the usual level and the ratio.

    ``usual`` is the median expected demand of the same weekday and hour over
    the year; rows are sorted by ``ratio``, highest first, and list the
    events behind the sector's demand that hour.
    """
    h = world._start(date, hour)
    rate = world.expected_rate()
    first = (date.weekday() - dt.date(world.year, 1, 1).weekday()) % 7
    usual = np.median(rate[first * 24 + hour :: 7 * 24], axis=0)
    expected = rate[h]
    ratio = expected / np.maximum(usual, 1e-9)
    titles = world.event_titles_by_sector(world.when(h))
    rows = [
        {
            "sector": s,
            "name": world.city.sector_names[s],
            "expected": float(expected[s]),
            "usual": float(usual[s]),
            "ratio": float(ratio[s]),
            "events": titles[s],
        }
        for s in range(world.city.n_sectors)
    ]
    return sorted(rows, key=lambda r: -r["ratio"])


# ====================================================================== weather
def synthetic_weather(year: int, seed: int) -> HourlyWeather:
    """Seeded hourly weather for ``year``: seasonal and daily temperature cycles, rain episodes, wind.

    New York-like: about 33 °F in January and 77 °F in July, some 120 rain
    episodes of 1–12 hours.  The evaluation evening (see
    :func:`evaluation_date`) is kept dry from noon so that its surge is an
    event surge, not a weather one.
    """
    rng = np.random.default_rng([seed, year, 16])
    n = hours_in_year(year)
    t = np.arange(n)
    days = n // 24
    doy, hod = t / 24.0, t % 24
    synoptic = _ar1(rng, days + 1, 0.8, 5.0)
    temp = (
        55.0
        - 22.0 * np.cos(2 * np.pi * (doy - 20) / 365.25)
        + 7.0 * np.cos(2 * np.pi * (hod - 15) / 24)
        + np.interp(doy, np.arange(days + 1), synoptic)
        + rng.normal(0.0, 1.0, n)
    )
    precip = np.zeros(n)
    n_rain = rng.poisson(120)
    for start, length, rate in zip(rng.integers(0, n, n_rain), np.minimum(rng.geometric(0.2, n_rain), 12), rng.exponential(0.05, n_rain)):
        stop = min(n, start + length)
        precip[start:stop] += rate * rng.gamma(2.0, 0.5, stop - start)
    wind = np.maximum(
        0.0,
        9.0 + 3.0 * np.cos(2 * np.pi * (doy - 20) / 365.25) + np.interp(doy, np.arange(days + 1), _ar1(rng, days + 1, 0.6, 3.0)) + rng.gamma(2.0, 1.0, n) - 2.0,
    )
    eve = (evaluation_date(year).timetuple().tm_yday - 1) * 24
    precip[eve + 12 : eve + 24] = 0.0
    return HourlyWeather(year=year, temp_f=temp, precip_in=np.round(precip, 3), wind_mph=wind, source=f"synthetic weather (seed {seed})")


def _ar1(rng: np.random.Generator, n: int, phi: float, sigma: float) -> np.ndarray:
    noise = rng.normal(0.0, sigma * np.sqrt(1 - phi**2), n)
    out = np.empty(n)
    out[0] = rng.normal(0.0, sigma)
    for i in range(1, n):
        out[i] = phi * out[i - 1] + noise[i]
    return out


def weather_factor(weather: HourlyWeather) -> np.ndarray:
    """Demand multiplier per hour: rain +15–30 %, below 25 °F +6 %, above 88 °F +5 %, gales +3 %."""
    rain = np.where(weather.precip_in >= 0.01, 0.15 + 0.15 * np.minimum(weather.precip_in / 0.25, 1.0), 0.0)
    return 1.0 + rain + 0.06 * (weather.temp_f < 25) + 0.05 * (weather.temp_f > 88) + 0.03 * (weather.wind_mph > 25)


# ====================================================================== space
#: Name fragments that identify anchor sectors on a real map (TLC zone names).
ANCHOR_NAMES: dict[str, tuple[str, ...]] = {
    "theater": ("theatre", "theater", "times sq"),
    "arena": ("penn", "madison sq", "arena"),
    "expo": ("javits", "hudson yards", "clinton west", "convention"),
    "park": ("park", "stadium", "battery"),
}


def find_anchors(city: City) -> dict[str, int]:
    """Sectors of the theatre district, arena, convention centre and festival park.

    ``city.info["anchors"]`` wins (``stadium`` is accepted for ``park``).
    Otherwise each anchor is the first sector whose name contains one of
    :data:`ANCHOR_NAMES`, tried in order (on the TLC zones: Times
    Sq/Theatre District, Penn Station/Madison Sq West, West Chelsea/Hudson
    Yards, Battery Park); anchors still missing take the
    largest remaining sectors by number of pickup intersections, so every map
    gets four distinct anchors deterministically.
    """
    given = dict(city.info.get("anchors", {}))
    size = np.bincount(city.node_sector[city.pickup], minlength=city.n_sectors)
    if "park" not in given and "stadium" in given:
        given["park"] = given["stadium"]
    anchors: dict[str, int] = {}
    taken: set[int] = set()
    names = [n.lower() for n in city.sector_names]
    for key, frags in ANCHOR_NAMES.items():
        if key in given:
            anchors[key] = int(given[key])
        else:
            hit = next((s for f in frags for s, n in enumerate(names) if s not in taken and size[s] > 0 and f in n), None)
            if hit is None:
                continue
            anchors[key] = hit
        taken.add(anchors[key])
    spare = [int(s) for s in np.argsort(-size, kind="stable") if int(s) not in taken]
    for key in ANCHOR_NAMES:
        if key not in anchors:
            anchors[key] = spare.pop(0) if spare else 0
    return anchors


def _metres(city: City) -> np.ndarray:
    """Node coordinates in metres (an equirectangular projection on lon/lat maps)."""
    if city.crs == "lonlat":
        lat0 = np.deg2rad(city.xy[:, 1].mean())
        return np.column_stack([city.xy[:, 0] * 111_320.0 * np.cos(lat0), city.xy[:, 1] * 110_540.0])
    return city.xy


def _centroids(city: City) -> np.ndarray:
    xy = _metres(city)
    S = city.n_sectors
    n = np.maximum(np.bincount(city.node_sector, minlength=S), 1)
    return np.column_stack([np.bincount(city.node_sector, weights=xy[:, k], minlength=S) / n for k in range(2)])


def _busyness(city: City, anchors: dict[str, int], rng: np.random.Generator) -> np.ndarray:
    """Relative activity per sector: highest around midtown (the anchors), plus seeded variety."""
    cent = _centroids(city)
    core = cent[[anchors["theater"], anchors["arena"], anchors["expo"]]].mean(axis=0)
    d = np.linalg.norm(cent - core, axis=1)
    busy = np.exp(rng.normal(0.0, 0.25, city.n_sectors)) * (0.45 + np.exp(-((d / 3000.0) ** 2)))
    busy[city.local_sectors(anchors["theater"])] *= 1.15
    for key, boost in (("theater", 1.3), ("arena", 1.3), ("expo", 1.2)):
        busy[anchors[key]] *= boost
    return busy


def _locale_counts(
    city: City,
    pois: Pois | None,
    busy: np.ndarray,
    anchors: dict[str, int],
    rng: np.random.Generator,
    notes: list[str],
) -> tuple[np.ndarray, Pois]:
    """n_λ(j) from the given points of interest, or from synthetic ones placed by ``busy``."""
    if pois is None:
        pois = synthetic_pois(city, busy, anchors, rng)
        notes.append(f"points of interest: {len(pois.kind)} synthetic")
    radius = POI_RADIUS.get(city.crs, POI_RADIUS["m"])
    counts = locale_counts_from_pois(city.xy, pois, radius)
    n_kind = {k: int(np.sum(pois.kind == k)) for k in LOCALE_TYPES}
    if n_kind["restaurant"] < 0.5 * n_kind["retail"]:
        # The NYC Planning POI file lists almost no restaurants (40 in Manhattan); restaurants follow
        # shops in Manhattan, so their counts are synthesised from the retail density.
        counts[:, LOCALE_TYPES.index("restaurant")] += counts[:, LOCALE_TYPES.index("retail")]
        notes.append(f"restaurants: only {n_kind['restaurant']} in the points of interest; counts synthesised from retail density")
    return counts + LOCALE_FLOOR, pois


def synthetic_pois(city: City, busy: np.ndarray, anchors: dict[str, int], rng: np.random.Generator) -> Pois:
    """Shops, restaurants, hotels and hospitals, denser in busy sectors; hotels cluster by the theatres."""
    S = city.n_sectors
    size = np.bincount(city.node_sector[city.pickup], minlength=S).astype(np.float64)
    near_theater = np.zeros(S)
    near_theater[city.local_sectors(anchors["theater"])] = 1.0
    plan = {
        "retail": (3000, size * busy),
        "restaurant": (3500, size * busy**1.3),
        "hotel": (250, size * busy**2 * (1.0 + 3.0 * near_theater)),
        "hospital": (10, size),
    }
    jitter = 40.0 if city.crs != "lonlat" else 0.0004
    xs, ys, kinds = [], [], []
    for kind, (total, weight) in plan.items():
        sectors = rng.choice(S, size=total, p=weight / weight.sum())
        nodes = _random_nodes(city, sectors, rng)
        xs.append(city.xy[nodes, 0] + rng.normal(0, jitter, total))
        ys.append(city.xy[nodes, 1] + rng.normal(0, jitter, total))
        kinds.append(np.full(total, kind))
    kind = np.concatenate(kinds)
    return Pois(np.concatenate(xs), np.concatenate(ys), kind, np.array([f"{k} {i}" for i, k in enumerate(kind)]))


def _random_nodes(city: City, sectors: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A uniformly random pickup-eligible intersection in each of ``sectors``."""
    order = np.flatnonzero(city.pickup)[np.argsort(city.node_sector[city.pickup], kind="stable")]
    bounds = np.searchsorted(city.node_sector[order], np.arange(city.n_sectors + 1))
    lo, hi = bounds[sectors], bounds[np.asarray(sectors) + 1]
    return order[lo + (rng.random(len(sectors)) * (hi - lo)).astype(np.int64)]


def _intensity(city: City, busy: np.ndarray, counts: np.ndarray, anchors: dict[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """Each sector's share of base demand, and its evening tilt.

    The tilt leans sectors rich in restaurants and hotels (and the theatre
    district) toward the evening and the others toward the morning; it is
    centred so that the citywide total keeps the base profile.
    """
    S = city.n_sectors
    size = np.bincount(city.node_sector[city.pickup], minlength=S).astype(np.float64)
    weight = busy * size**0.7
    intensity = weight / weight.sum()
    by_kind = np.stack([np.bincount(city.node_sector, weights=counts[:, k], minlength=S) for k in range(len(LOCALE_TYPES))], axis=1)
    evening = by_kind[:, [1, 2]].sum(axis=1) / np.maximum(by_kind.sum(axis=1), 1e-9)
    z = (evening - evening.mean()) / max(evening.std(), 1e-9)
    tilt = np.clip(0.12 * z, -0.25, 0.25)
    tilt[anchors["theater"]] += 0.15
    tilt -= np.dot(intensity, tilt)
    return intensity, tilt


def _base_rate(city: City, year: int, weather: HourlyWeather, intensity: np.ndarray, tilt: np.ndarray) -> np.ndarray:
    """Expected requests per sector-hour without events: REF_RATE × profile × day × month × weather × sector."""
    days = (dt.date(year + 1, 1, 1) - dt.date(year, 1, 1)).days
    dates = [dt.date(year, 1, 1) + dt.timedelta(days=d) for d in range(days)]
    off = holidays(year)
    citywide = np.empty((days, 24))
    for d, date in enumerate(dates):
        kind = "sunday" if date in off else day_type(date)
        prof = PROFILES[kind] * (FRIDAY_NIGHT if date.weekday() == 4 and kind == "weekday" else 1.0)
        citywide[d] = prof * DAY_FACTOR[date.weekday()] * MONTH_FACTOR[date.month - 1]
    citywide = citywide.ravel() * weather_factor(weather) * REF_RATE
    shape = 1.0 + tilt[None, :] * np.tile(TILT, days)[:, None]
    return citywide[:, None] * intensity[None, :] * shape


def _surge_split(city: City, intensity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``[venue sector, pickup sector]`` shares of arrival and departure pickups.

    Arrivals and departures are picked up mostly in the venue's own sector
    (:data:`ARRIVAL_HOME_SHARE`, :data:`DEPARTURE_HOME_SHARE`), the rest in
    the adjacent sectors in proportion to their base demand.
    """
    S = city.n_sectors
    out = []
    for home in (ARRIVAL_HOME_SHARE, DEPARTURE_HOME_SHARE):
        split = np.zeros((S, S))
        for v in range(S):
            nb = np.flatnonzero(city.sector_adj[v])
            nb = nb[intensity[nb] > 0]
            if len(nb) == 0:
                split[v, v] = 1.0
                continue
            split[v, v] = home
            split[v, nb] = (1.0 - home) * intensity[nb] / intensity[nb].sum()
        out.append(split)
    return out[0], out[1]


def gravity_od(city: City, intensity: np.ndarray) -> np.ndarray:
    """β: drop-off sector ∝ intensity × exp(−hops / L), with L set for a mean trip of :data:`TARGET_TRIP_HOPS`.

    Hops are the mean shortest-path hop counts between the pickup
    intersections of two sectors; rows sum to one.
    """
    S = city.n_sectors
    nodes = np.flatnonzero(city.pickup)
    onehot = np.zeros((len(nodes), S))
    onehot[np.arange(len(nodes)), city.node_sector[nodes]] = 1.0
    size = np.maximum(onehot.sum(axis=0), 1.0)
    hops = onehot.T @ city.dist[np.ix_(nodes, nodes)].astype(np.float64) @ onehot / np.outer(size, size)

    def beta(length: float) -> np.ndarray:
        w = intensity[None, :] * np.exp(-hops / length)
        return w / np.maximum(w.sum(axis=1, keepdims=True), 1e-300)

    lo, hi = 1.0, 500.0
    for _ in range(40):  # mean trip length grows with L: bisect on a log scale
        mid = np.sqrt(lo * hi)
        mean = float(intensity @ (beta(mid) * hops).sum(axis=1))
        lo, hi = (mid, hi) if mean < TARGET_TRIP_HOPS else (lo, mid)
    return beta(np.sqrt(lo * hi))


# ====================================================================== venues
VENUE_PLAN: tuple[tuple[str, int, int, int], ...] = (
    # (kind, count, min capacity, max capacity)
    ("theatre", 40, 500, 1900),
    ("arena", 1, 19000, 19000),
    ("convention center", 1, 20000, 20000),
    ("festival grounds", 1, 40000, 40000),
    ("park", 3, 5000, 15000),
    ("concert hall", 45, 300, 3000),
    ("stage", 10, 150, 800),
    ("conference center", 30, 300, 2500),
    ("community center", 169, 50, 600),
)
#: Venue kinds spread over the whole map (every sector with pickups gets at least one of each kind
#: while there are enough), so that event surges are not confined to midtown.
_SPREAD_KINDS = ("concert hall", "conference center")
_SURNAMES = (
    "Gershwin", "Majestic", "Imperial", "Shubert", "Booth", "Barrymore", "Belasco", "Ambassador", "Lyceum", "Hudson",
    "Palace", "Lunt", "Winter", "Minskoff", "Richard", "August", "Walter", "Eugene", "Neil", "Samuel", "Helen",
    "Hayes", "Nederlander", "Broadhurst", "Golden", "Jacobs", "Longacre", "Marquis", "Cort", "Stein", "Hirschfeld",
    "Lyric", "Vivian", "Circle", "Studio", "Friedman", "Music Box", "Schoenfeld", "Brooks", "Todd",
)
_HALL_NAMES = ("Hall", "Ballroom", "Room", "Music Hall", "Club", "Lounge", "Stage", "Garage", "Loft")
_COMMUNITY_KINDS = ("Community Center", "Library", "Church Hall", "Gallery", "Recreation Center", "Settlement House")


def _venues(city: City, anchors: dict[str, int], busy: np.ndarray, rng: np.random.Generator) -> list[Venue]:
    """About 300 venues: theatres around the theatre anchor, the arena, convention centre and park at
    their anchors, concert halls and conference centres in every sector (more in busy ones),
    everything else spread over sectors in proportion to their busyness."""
    S = city.n_sectors
    has_nodes = np.bincount(city.node_sector[city.pickup], minlength=S) > 0
    p_busy = np.where(has_nodes, busy, 0.0)
    p_busy = p_busy / p_busy.sum()
    theatre_nb = [s for s in city.local_sectors(anchors["theater"]) if s != anchors["theater"] and has_nodes[s]]
    out: list[Venue] = []
    for kind, count, cmin, cmax in VENUE_PLAN:
        if kind == "theatre":
            sectors = np.array([anchors["theater"] if rng.random() < 0.7 or not theatre_nb else rng.choice(theatre_nb) for _ in range(count)])
        elif kind in ("arena", "convention center", "festival grounds"):
            key = {"arena": "arena", "convention center": "expo", "festival grounds": "park"}[kind]
            sectors = np.full(count, anchors[key])
        elif kind in _SPREAD_KINDS:
            p_spread = np.where(has_nodes, np.sqrt(busy), 0.0)
            p_spread = p_spread / p_spread.sum()
            cover = rng.choice(S, size=min(count, int(has_nodes.sum())), replace=False, p=p_spread)
            sectors = np.concatenate([cover, rng.choice(S, size=count - len(cover), p=p_spread)]).astype(np.int64)
        else:
            sectors = rng.choice(S, size=count, p=p_busy)
        nodes = _random_nodes(city, sectors, rng)
        caps = np.round(rng.uniform(cmin, cmax, count), -1).astype(int) if cmax > cmin else np.full(count, cmin)
        for i in range(count):
            out.append(
                Venue(
                    venue_id=f"V{len(out):03d}",
                    name=_venue_name(kind, i, city.sector_names[sectors[i]], rng),
                    node=int(nodes[i]),
                    sector=int(sectors[i]),
                    capacity=int(caps[i]),
                    kind=kind,
                )
            )
    return out


def _venue_name(kind: str, i: int, sector_name: str, rng: np.random.Generator) -> str:
    if kind == "theatre":
        return f"{_SURNAMES[i % len(_SURNAMES)]} Theatre"
    if kind == "arena":
        return "Garden Arena"
    if kind == "convention center":
        return "Hudson Convention Center"
    if kind == "festival grounds":
        return "Riverside Festival Grounds"
    if kind == "park":
        return f"{sector_name} Park" if i == 0 else f"Pier {40 + 17 * i}"
    if kind == "concert hall":
        return f"The {texts.BAND_ADJ[i % len(texts.BAND_ADJ)]} {_HALL_NAMES[i % len(_HALL_NAMES)]}"
    if kind == "stage":
        return f"{_SURNAMES[(3 * i + 7) % len(_SURNAMES)]} Playhouse"
    if kind == "conference center":
        return f"{sector_name} Conference Center" if i % 3 == 0 else f"Grand {_SURNAMES[(5 * i) % len(_SURNAMES)]} Hotel"
    return f"{sector_name} {_pick(rng, _COMMUNITY_KINDS)}"


# ====================================================================== events
@dataclass(frozen=True)
class _Spec:
    """An event before its text: what drives its attendance, and where and when."""

    venue: int
    category: str
    name: str
    start: dt.datetime
    minutes: int
    popularity: float
    sentiment: float
    capacity: int
    cue: str | None = None
    group: int = -1  # events of one production or multi-day show share their reviews


#: Popularity shift by month for stage shows (January slump, holiday peak).
_STAGE_MONTH = (-0.12, -0.08, -0.02, 0.0, 0.02, 0.03, 0.04, 0.03, -0.04, 0.0, 0.04, 0.10)
#: Relative chance that an arena or club event falls on each weekday (Mon … Sun).
_NIGHT_WEIGHT = np.array([0.8, 1.1, 1.1, 0.6, 1.3, 1.3, 1.0])
_CLUB_WEIGHT = np.array([0.5, 0.7, 0.9, 1.0, 1.5, 1.6, 0.8])


def _schedule(venues: list[Venue], year: int, rng: np.random.Generator) -> list[_Spec]:
    """A year of events at the venues, with the evaluation evening's surge guaranteed."""
    by_kind: dict[str, list[int]] = {}
    for i, v in enumerate(venues):
        by_kind.setdefault(v.kind, []).append(i)
    days = [dt.date(year, 1, 1) + dt.timedelta(days=d) for d in range(hours_in_year(year) // 24)]
    eve = evaluation_date(year)
    specs: list[_Spec] = []
    groups = itertools.count()
    specs += _broadway(venues, by_kind["theatre"], days, rng, groups)
    specs += _arena(venues[by_kind["arena"][0]], by_kind["arena"][0], days, eve, rng)
    specs += _convention(venues[by_kind["convention center"][0]], by_kind["convention center"][0], days, eve, rng, groups)
    specs += _festivals(venues, by_kind["festival grounds"] + by_kind["park"], days, rng)
    specs += _small_events(venues, by_kind, days, year, rng)
    return specs


def _beta(rng: np.random.Generator, a: float, b: float) -> float:
    return float(rng.beta(a, b))


def _pick(rng: np.random.Generator, options: Sequence[str]) -> str:
    return options[int(rng.integers(len(options)))]


def _at(day: dt.date, hour: float) -> dt.datetime:
    return dt.datetime.combine(day, dt.time()) + dt.timedelta(minutes=round(hour * 60))


def _broadway(venues: list[Venue], theatres: list[int], days: list[dt.date], rng: np.random.Generator, groups: Iterator[int]) -> list[_Spec]:
    """Runs of productions at each theatre; performances Tue–Sun evenings plus Wed/Sat/Sun matinees.

    Ten hits run all year; other productions run 8–40 weeks with dark weeks
    between.  A performance's popularity is its production's, shifted by
    month, weekend, opening night (+0.2) and final week (+0.12).
    """
    hits = list(texts.BROADWAY_HITS)
    others = [str(n) for n in rng.permutation(texts.BROADWAY_SHOWS)]
    specs: list[_Spec] = []
    n_days = len(days)
    for k, t in enumerate(theatres):
        d = 0 if k < len(hits) else int(rng.integers(-120, 20))
        while d < n_days:
            if k < len(hits):
                name, length = hits[k], n_days
                pop, sent = _beta(rng, 9, 2), _beta(rng, 7, 2)
            else:
                name = others.pop(0) if others else f"{_pick(rng, texts.BROADWAY_SHOWS)} (Revival)"
                length = int(rng.integers(8, 41)) * 7
                pop, sent = _beta(rng, 2.5, 2.5), _beta(rng, 2.5, 1.8)
            first, last = d, d + length - 1
            evening = 19.0 if rng.random() < 0.4 else 20.0
            sunday_evening = rng.random() < 0.3
            wed_matinee = rng.random() < 0.6
            minutes = int(rng.integers(130, 171))
            group = next(groups)
            for day_i in range(max(first, 0), min(last + 1, n_days)):
                day = days[day_i]
                wd = day.weekday()
                slots = []
                if 1 <= wd <= 5 or (wd == 6 and sunday_evening):
                    slots.append(19.0 if wd in (1, 6) else evening)
                if (wd == 2 and wed_matinee) or wd in (5, 6):
                    slots.append(14.0)
                for slot in slots:
                    cue = "Opening Night" if day_i == first and first > 0 and slot > 17 else None
                    if cue is None and last < n_days - 1 and day_i > last - 7:
                        cue = "Final Week"
                    p = pop + _STAGE_MONTH[day.month - 1] + 0.05 * (wd in (4, 5) and slot > 17) - 0.05 * (slot < 17)
                    p += 0.2 * (cue == "Opening Night") + 0.12 * (cue == "Final Week") + rng.normal(0.0, 0.04)
                    specs.append(_Spec(t, "performing-arts", name, _at(day, slot), minutes, float(np.clip(p, 0.02, 1.0)), sent, venues[t].capacity, cue, group))
            d = last + 1 + int(rng.integers(1, 6)) * 7
    return specs


def _pick_days(rng: np.random.Generator, candidates: list[int], days: list[dt.date], weights: np.ndarray, n: int, taken: set[int]) -> list[int]:
    """``n`` distinct days among ``candidates`` not in ``taken``, weighted by weekday."""
    free = [d for d in candidates if d not in taken]
    if not free or n <= 0:
        return []
    w = np.array([weights[days[d].weekday()] for d in free])
    chosen = rng.choice(free, size=min(n, len(free)), replace=False, p=w / w.sum())
    taken.update(int(c) for c in chosen)
    return sorted(int(c) for c in chosen)


def _arena(venue: Venue, vi: int, days: list[dt.date], eve: dt.date, rng: np.random.Generator) -> list[_Spec]:
    """Basketball, hockey, summer basketball, concerts, college games and specials: ~3 nights a week.

    The evaluation evening always has a sold-out marquee game (a national-TV 20:00 tip-off).
    """
    n = len(days)
    idx = {day: i for i, day in enumerate(days)}
    season = [i for i, d in enumerate(days) if d <= dt.date(d.year, 4, 10) or d >= dt.date(d.year, 10, 20)]
    summer = [i for i, d in enumerate(days) if dt.date(d.year, 5, 15) <= d <= dt.date(d.year, 9, 15)]
    taken = {idx[eve]}
    specs = [_Spec(vi, "sports", "Knicks vs. Celtics", _at(eve, 20.0), 150, 0.95, 0.85, venue.capacity)]
    plan = (
        ("basketball", "sports", season, 40, 19.5, 150, (5, 2)),
        ("hockey", "sports", season, 41, 19.0, 165, (5, 2)),
        ("wnba", "sports", summer, 18, 19.5, 140, (3, 3)),
        ("college", "sports", season, 10, 19.0, 130, (2, 3)),
        ("concert", "concerts", list(range(n)), 42, 20.0, 180, (6, 2)),
        ("special", "sports", list(range(n)), 12, 19.5, 180, (3, 2.5)),
    )
    for kind, category, candidates, count, hour, minutes, (a, b) in plan:
        for d in _pick_days(rng, candidates, days, _NIGHT_WEIGHT, count, taken):
            day = days[d]
            if kind in texts.TEAMS:
                home, rivals = texts.TEAMS[kind]
                rival = _pick(rng, rivals)
                name = f"{home} vs. {rival}"
                pop = _beta(rng, a, b) + 0.12 * (rival in texts.MARQUEE)
                cap = venue.capacity if kind in ("basketball", "hockey") else 10000
            elif kind == "concert":
                name, pop, cap = f"The {_pick(rng, texts.BAND_ADJ)} {_pick(rng, texts.BAND_NOUN)}: Arena Tour", _beta(rng, a, b), venue.capacity
            else:
                name, pop, cap = _pick(rng, texts.SPORTS_SPECIALS), _beta(rng, a, b), venue.capacity
            start_h = hour if day.weekday() < 5 or rng.random() < 0.6 else 13.0
            specs.append(_Spec(vi, category, name, _at(day, start_h), minutes, float(min(pop, 1.0)), _beta(rng, 4, 2), cap))
    return specs


def _convention(venue: Venue, vi: int, days: list[dt.date], eve: dt.date, rng: np.random.Generator, groups: Iterator[int]) -> list[_Spec]:
    """Expos and conferences of 2–4 days, one at a time, opening 10:00 (conferences 8:30) and closing 17:00–19:00.

    The evaluation date is the closing day of a big tech expo that ends at 19:00.
    """
    idx = {day: i for i, day in enumerate(days)}
    e = idx[eve]
    busy = set(range(e - 3, e + 2))  # the eval show plus a setup day either side
    specs: list[_Spec] = []
    g = next(groups)
    for k, (pop, hours) in enumerate(((0.72, (10, 18)), (0.78, (10, 18)), (0.93, (10, 19)))):
        cue = "Opening Day" if k == 0 else "Final Day" if k == 2 else None
        day = days[e - 2 + k]
        specs.append(_Spec(vi, "expos", f"NY Tech Expo {day.year}", _at(day, hours[0]), 60 * (hours[1] - hours[0]), pop, 0.8, 18000, cue, g))
    shows = [str(s) for s in rng.permutation(texts.EXPOS) if s != "NY Tech Expo"]
    n_days = len(days)
    for j in range(34):
        conference = j % 4 == 3
        length = int(rng.integers(2, 4 if conference else 5))
        for _ in range(50):  # find a free slot; give up on this show if the calendar is full
            d0 = int(rng.integers(0, n_days - length))
            span = set(range(d0 - 1, d0 + length + 1))
            if not span & busy and (conference or days[d0].weekday() < 5):
                break
        else:
            continue
        busy |= span
        if conference:
            name = f"{_pick(rng, texts.CONF_TOPICS)} {_pick(rng, texts.CONF_FORMATS)} {days[d0].year}"
            category, cap, open_h = "conferences", int(rng.integers(30, 81)) * 100, 8.5
        else:
            name, category, cap, open_h = f"{shows[j % len(shows)]} {days[d0].year}", "expos", int(rng.integers(10, 41)) * 500, 10.0
        base, sent = _beta(rng, 3, 2), _beta(rng, 3, 2)
        close_h = float(rng.choice([17.0, 17.5, 18.0, 19.0]))
        g = next(groups)
        for k in range(length):
            cue = "Opening Day" if k == 0 else "Final Day" if k == length - 1 else None
            pop = float(np.clip(base + 0.05 * (k == length - 1) + rng.normal(0, 0.03), 0.02, 1.0))
            specs.append(_Spec(vi, category, name, _at(days[d0 + k], open_h), round(60 * (close_h - open_h)), pop, sent, cap, cue, g))
    return specs


def _festivals(venues: list[Venue], grounds: list[int], days: list[dt.date], rng: np.random.Generator) -> list[_Spec]:
    """Weekend festivals May–October at the festival grounds and parks, plus winter markets and lights."""
    specs: list[_Spec] = []
    for rank, vi in enumerate(grounds):
        venue = venues[vi]
        weekend = [i for i, d in enumerate(days) if d.weekday() >= 5 and 5 <= d.month <= 10]
        share = 0.7 if rank == 0 else 0.2
        for d in weekend:
            if rng.random() < share:
                day = days[d]
                name = _pick(rng, texts.FESTIVALS)
                cap = int(venue.capacity * rng.uniform(0.5, 1.0)) // 500 * 500
                specs.append(_Spec(vi, "festivals", f"{name} {day.year}", _at(day, 11.0 + rng.integers(0, 3)), int(rng.integers(6, 10)) * 60, _beta(rng, 3, 2), _beta(rng, 4, 2), cap))
        if rank == 0:
            for d in (i for i, dd in enumerate(days) if dd.month == 12 and dd.weekday() >= 5 and dd.day < 25):
                day = days[d]
                name = _pick(rng, texts.WINTER_FESTIVALS)
                specs.append(_Spec(vi, "festivals", f"{name} {day.year}", _at(day, 12.0), 8 * 60, _beta(rng, 4, 2), _beta(rng, 4, 2), venue.capacity // 2))
    return specs


def _small_events(venues: list[Venue], by_kind: dict[str, list[int]], days: list[dt.date], year: int, rng: np.random.Generator) -> list[_Spec]:
    """Club concerts, small-stage shows, hotel conferences and talks, and community events.

    These are the irregular events that drive the evening surges: a concert
    hall holds a show on about one day in five and a conference centre an
    event on about two weekdays in five, on days drawn at random, with
    popularity (hence attendance and taxi trips) varying widely from one
    event to the next.  Evening concerts start 19:30–21:00 (arrivals in the
    19 h hour); weekend shows start at 15:00–15:30 (ending around 17:00) or
    18:00; day conferences close at 17:00–17:30 and evening talks and
    receptions start at 18:00–18:30 (arrivals at 17 h, departures around 19 h).
    """
    specs: list[_Spec] = []
    n = len(days)
    name_rng = random.Random(int(rng.integers(1 << 30)))
    weekdays = [i for i, d in enumerate(days) if d.weekday() < 5]
    weekend = np.array([0.05, 0.05, 0.05, 0.05, 0.1, 1.0, 1.0])
    plan = (
        ("concert hall", "concerts", 60, _CLUB_WEIGHT, (19.5, 20.0, 20.0, 20.5, 21.0), (120, 181), (2, 2.5)),
        ("concert hall", "concerts", 16, weekend, (15.0, 15.5, 18.0, 18.0), (100, 131), (2, 2.5)),
        ("stage", "performing-arts", 60, _CLUB_WEIGHT, (19.0, 19.5, 21.5), (90, 121), (2, 3)),
        ("conference center", "conferences", 24, None, (8.5,), (510, 541), (2, 3)),
        ("conference center", "conferences", 75, None, (18.0, 18.0, 18.5), (60, 101), (2, 2.5)),
        ("community center", "community", 4, np.array([1.0, 1.0, 1.0, 1.0, 0.8, 1.2, 1.0]), (18.0, 18.5, 10.0), (90, 181), (1.3, 4)),
        ("park", "community", 3, np.array([0.5, 0.5, 0.5, 0.5, 0.5, 1.5, 1.5]), (10.0, 11.0), (120, 241), (1.5, 3)),
    )
    for kind, category, per_year, weights, hours, (mlo, mhi), (a, b) in plan:
        for vi in by_kind[kind]:
            venue = venues[vi]
            count = int(rng.poisson(per_year))
            if weights is None:
                chosen = sorted(int(d) for d in rng.choice(weekdays, size=min(count, len(weekdays)), replace=False))
            else:
                chosen = _pick_days(rng, list(range(n)), days, weights, count, set())
            for d in chosen:
                day = days[d]
                hour = float(rng.choice(hours))
                minutes = int(rng.integers(mlo, mhi))
                if category == "concerts":
                    name = texts.concert_name(name_rng)
                elif category == "performing-arts":
                    name = name_rng.choice(texts.SMALL_STAGE)
                elif category == "conferences":
                    name = texts.conference_name(name_rng, year)
                else:
                    name = name_rng.choice(texts.COMMUNITY)
                specs.append(_Spec(vi, category, name, _at(day, hour), minutes, _beta(rng, a, b), _beta(rng, 3, 2), venue.capacity))
    return specs


def fill_rate(popularity: np.ndarray, sentiment: np.ndarray) -> np.ndarray:
    """Share of capacity that attends: rises with popularity, and with sentiment."""
    return np.clip(0.05 + np.asarray(popularity) ** 1.1 * (0.65 + 0.4 * np.asarray(sentiment)), 0.03, 1.0)


_UNITS = {"convention center": "visitor", "festival grounds": "visitor", "park": "visitor", "conference center": "person", "community center": "person"}


def _events(specs: list[_Spec], venues: list[Venue], rng: random.Random) -> tuple[list[Event], np.ndarray]:
    """Events with title, description and reviews; returns them sorted by start and their attendance."""
    pop = np.array([s.popularity for s in specs])
    sent = np.array([s.sentiment for s in specs])
    cap = np.array([s.capacity for s in specs], dtype=np.float64)
    attendance = np.round(cap * fill_rate(pop, sent))
    # Reviews of a production or multi-day show speak to its typical night, not to one performance.
    group = np.array([s.group for s in specs])
    grouped = group >= 0
    n_group = np.bincount(group[grouped])
    group_pop = np.bincount(group[grouped], weights=pop[grouped]) / np.maximum(n_group, 1)
    group_att = np.bincount(group[grouped], weights=attendance[grouped]) / np.maximum(n_group, 1)
    group_reviews: dict[int, tuple[str, ...]] = {}
    events = []
    for i, s in enumerate(specs):
        venue = venues[s.venue]
        kind = next((k.lower() for k in _COMMUNITY_KINDS if venue.name.endswith(k)), venue.kind)
        where = texts.venue_phrase(venue.name, kind, s.capacity, _UNITS.get(venue.kind, "seat"))
        title = texts.title(rng, s.category, s.name, s.popularity, s.cue)
        if s.group < 0:
            reviews = texts.reviews(rng, s.category, s.popularity, s.sentiment, float(attendance[i]))
        elif s.group not in group_reviews:
            reviews = group_reviews[s.group] = texts.reviews(rng, s.category, float(group_pop[s.group]), s.sentiment, float(group_att[s.group]))
        else:
            reviews = group_reviews[s.group]
        events.append(
            Event(
                event_id="",
                title=title,
                description=texts.description(rng, s.category, title, where, s.popularity, s.sentiment, s.start),
                category=s.category,
                start=s.start,
                end=s.start + dt.timedelta(minutes=s.minutes),
                sector=venue.sector,
                node=venue.node,
                venue_id=venue.venue_id,
                reviews=reviews,
                attendance=float(attendance[i]),
            )
        )
    order = sorted(range(len(events)), key=lambda i: (events[i].start, events[i].venue_id, events[i].title))
    out = [dataclasses.replace(events[i], event_id=f"E{k:05d}") for k, i in enumerate(order)]
    return out, attendance[order]


def _surges(events: list[Event], attendance: np.ndarray, year: int, S: int, scale: float):
    """Expected event trips per hour by venue sector, arriving and departing, and per event-hour rows.

    Arrival requests enter 5 + Gamma(2.5, 12) minutes before the start (mean
    35 min), departures 2 + Gamma(1.5, 12) minutes after the end (mean 20
    min).  Events longer than :data:`LONG_EVENT_MIN` (expos, festivals) also
    spread half their arrivals over their first half and 40 % of their
    departures over their second half.
    """
    n_hours = hours_in_year(year)
    origin = dt.datetime(year, 1, 1)
    start = np.array([(e.start - origin).total_seconds() / 60 for e in events])
    dur = np.array([(e.end - e.start).total_seconds() / 60 for e in events])
    sector = np.array([e.sector for e in events])
    share = np.array([TAXI_SHARE[e.category] for e in events]).reshape(-1, 2)
    trips_arr = attendance * share[:, 0]
    trips_dep = attendance * share[:, 1]
    long = dur > LONG_EVENT_MIN
    w_pre = np.where(long, 0.5, 1.0)[:, None]
    w_post = np.where(long, 0.6, 1.0)[:, None]
    half = (dur / 2)[:, None]
    s0 = start[:, None]
    e0 = (start + dur)[:, None]

    def g_arr(t):  # share of arrivals entered before minute t
        return w_pre * (1 - gammainc(2.5, np.maximum(s0 - t - 5, 0) / 12.0)) + (1 - w_pre) * np.clip((t - s0) / half, 0, 1)

    def g_dep(t):
        return w_post * gammainc(1.5, np.maximum(t - e0 - 2, 0) / 12.0) + (1 - w_post) * np.clip((t - s0 - half) / half, 0, 1)

    span = int(np.max(np.ceil((start + dur) / 60) - start // 60)) + 4
    hours = (start // 60)[:, None] + np.arange(-4, span + 1)[None, :]
    t0, t1 = hours * 60, hours * 60 + 60
    f_arr = g_arr(t1) - g_arr(t0)
    f_dep = g_dep(t1) - g_dep(t0)
    ok = (hours >= 0) & (hours < n_hours) & ((f_arr * trips_arr[:, None] + f_dep * trips_dep[:, None]) > 1e-3)
    a = f_arr * trips_arr[:, None] * scale
    d = f_dep * trips_dep[:, None] * scale
    ev, col = np.nonzero(ok)
    h = hours[ev, col].astype(np.int64)
    arrivals = np.bincount(h * S + sector[ev], weights=a[ev, col], minlength=n_hours * S).reshape(n_hours, S)
    departures = np.bincount(h * S + sector[ev], weights=d[ev, col], minlength=n_hours * S).reshape(n_hours, S)
    order = np.argsort(h, kind="stable")
    rows = (ev[order], h[order], a[ev, col][order], d[ev, col][order])
    return arrivals, departures, rows


__all__ = [
    "EVAL_DATE",
    "DemandWorld",
    "RecordedWorld",
    "SyntheticWorld",
    "evaluation_date",
    "gravity_od",
    "surge_report",
    "synthetic_pois",
    "synthetic_weather",
    "synthetic_world",
]
