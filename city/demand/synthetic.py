"""The synthetic demand world: a seeded year of base demand and event surges on any map.

Base demand per sector-hour is the real citywide profile
(:mod:`city.demand.profile`) spread over sectors by their intensity, or, on
a real map with a zone profile, the real per-sector rates and β scaled by
``share``, or, with a city's real hourly trip totals, the real level of every
hour split over sectors (:mod:`city.demand.real_level`).  Events come on top (:mod:`city.demand.attendance`): arrivals
before an event are trips that *end* at its venue, their pickups spread over
the map by the origin–destination model (where trips to the venue's sector
come from); departures after its end are pickups *at* the venue, going back
where the arrivals came from.
"""

from __future__ import annotations

import datetime as dt
import random
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from city.demand.attendance import draw_attendance, event_trips, surges, write_events
from city.demand.climate import synthetic_weather
from city.demand.dates import HOLIDAY_COUNTRY, day_kind, holiday_dates
from city.demand.geography import (
    busyness,
    find_anchors,
    gravity_od,
    intensity_and_tilt,
    locale_counts,
)
from city.demand.profile import FLEET_SHARE, TILT, base_rate, profile_base_rate
from city.demand.real_level import BASE_FLOOR, day_kinds, default_share, real_base, sector_split
from city.demand.naming import NEW_YORK, Naming
from city.demand.venues import EventSpec, make_venues, schedule
from city.demand.world import DemandWorld, HourTrips, check_seed_year
from city.errors import ConfigError
from city.graph import City
from city.io.poi import Pois
from city.io.weather import HourlyWeather

if TYPE_CHECKING:
    from city.io.hourly_totals import HourlyTotals
    from city.io.trips import ZoneProfile
    from city.io.zone_hourly import ZoneHourly


class SyntheticWorld(DemandWorld):
    """A seeded synthetic year of demand on any map; the same arguments always give the same world.

    Extra attributes: ``anchors`` (sector of the theatre district, arena,
    convention centre and festival park), ``intensity`` (each sector's share
    of base demand), ``demand_scale``, ``share`` (of a zone profile's real
    counts, or of the real hourly totals), ``base_source`` (what the base
    demand is made of, in words), ``demand_source`` (the same, recorded
    in results files) and ``event_specs`` (by event id, the
    :class:`~city.demand.venues.EventSpec` its text and attendance were
    drawn from: the announced attendance drivers, as the world records them).

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
    zone_profile : ZoneProfile, optional
        Real zone-to-zone trip rates (:func:`city.io.trips.read_zone_profile`) for the base demand and β.
    share : float, optional
        The fleet's share of the real market (default :data:`~city.demand.profile.FLEET_SHARE`, ≈ 1.7 %):
        it scales the zone profile's trips, or the real profile's 19 h level on a map without one,
        and the event-goers' trips.  With ``hourly_totals`` it scales the real totals, and the default
        is :func:`~city.demand.real_level.default_share`.
    hourly_totals : HourlyTotals, optional
        The city's real trips of every hour of ``year`` (:func:`city.io.hourly_totals.read_hourly_totals`):
        the base demand is then the real level of each hour (:mod:`city.demand.real_level`); weather
        then only moves event attendance.
    zone_hourly : ZoneHourly, optional
        Real trips per zone and hour (:func:`city.io.zone_hourly.read_zone_hourly`) for the weekend and
        holiday split of ``hourly_totals``.
    holidays : (country, subdivision)
        Whose public holidays run on a Sunday profile (the ``holidays`` package); US federal by default.
    schedules : dict, optional
        Occupancy schedules (:func:`city.io.occupancy.read_occupancy_csv`) for the assignment of
        requests to intersections; the built-in DOE ones otherwise.
    naming : Naming
        The venues', teams' and flagship shows' names (:mod:`city.demand.naming`); New York's by
        default, a city's own with :func:`city.demand.naming.neutral`.  Only words change: the
        events' times, places and attendance are the same.
    """

    def __init__(
        self,
        city: City,
        year: int = 2022,
        seed: int = 0,
        weather: HourlyWeather | None = None,
        pois: Pois | None = None,
        demand_scale: float = 1.0,
        zone_profile: "ZoneProfile | None" = None,
        share: float | None = None,
        holidays: tuple[str, str | None] = (HOLIDAY_COUNTRY, None),
        schedules: dict | None = None,
        hourly_totals: "HourlyTotals | None" = None,
        zone_hourly: "ZoneHourly | None" = None,
        naming: Naming = NEW_YORK,
    ) -> None:
        check_seed_year(seed, year)
        if not demand_scale > 0:
            raise ConfigError(f"demand_scale must be positive, got {demand_scale}")
        totals = hourly_totals.year(year) if hourly_totals is not None else None
        if share is None:
            share = FLEET_SHARE if totals is None else default_share(totals, day_kinds(year, holiday_dates(year, *holidays)), year)
        if not 0 < share <= 1:
            raise ConfigError(f"share must be in (0, 1], got {share}")
        notes: list[str] = []
        if weather is None:
            weather = synthetic_weather(year, seed)
            notes.append(f"weather: {weather.source}")
        self.anchors = find_anchors(city)
        busy = busyness(city, self.anchors, np.random.default_rng([seed, 11]))
        counts, pois = locale_counts(city, pois, busy, self.anchors, np.random.default_rng([seed, 12]), notes)
        self.intensity, tilt = intensity_and_tilt(city, busy, counts, self.anchors)
        self.demand_scale = float(demand_scale)
        self.share = float(share)
        venues = make_venues(city, self.anchors, busy, np.random.default_rng([seed, 13]), naming)
        specs = schedule(venues, year, np.random.default_rng([seed, 14]), naming)
        events, specs = write_events(specs, venues, random.Random(f"surge-texts-{seed}"))
        events, attendance = draw_attendance(specs, events, venues, weather, seed)
        super().__init__(city, year, seed, venues, events, weather, counts, pois, notes, holidays=holidays, schedules=schedules)
        self._real_totals: np.ndarray | None = None
        self.event_specs: dict[str, EventSpec] = {e.event_id: s for e, s in zip(events, specs)}
        self.hourly_totals_source = None if hourly_totals is None else hourly_totals.source

        S = city.n_sectors
        if zone_profile is not None:
            if zone_profile.trips.shape[2] != S:
                raise ConfigError(f"zone profile {zone_profile.source} has {zone_profile.trips.shape[2]} sectors, the city {S}")
            hourly = zone_profile.hourly()
            self._base = profile_base_rate(year, weather, hourly.sum(axis=3), self.share, self.holidays) * self.demand_scale
            self._profile_beta = zone_profile.beta()
            daily = hourly.sum(axis=(0, 1))
            self.intensity = daily.sum(axis=1) / daily.sum()
            static = daily / np.maximum(daily.sum(axis=1, keepdims=True), 1e-300)
            self._static_beta = np.where(daily.sum(axis=1, keepdims=True) > 0, static, 1.0 / S)
            self.base_source = f"zone profile {zone_profile.source} × share {self.share:g}"
            notes.append(f"base demand: {self.base_source}")
        else:
            self._base = base_rate(year, weather, self.intensity, tilt, self.share, self.holidays) * self.demand_scale
            self._profile_beta = None
            self._static_beta = gravity_od(city, self.intensity)
            self.base_source = f"real hourly profile (city.demand.profile.PROFILE) × share {self.share:g} × sector intensity"
        # p(pickup sector | trip ends in sector v): where trips to v come from (base flows into v).
        # A sector no trip ends in (possible in a sparse zone profile) draws its visitors locally.
        inflow = self.intensity[:, None] * self._static_beta
        into = inflow.sum(axis=0, keepdims=True)
        self._origin = np.where(into > 0, inflow / np.where(into > 0, into, 1.0), np.eye(S)).T
        trips_arr, trips_dep = event_trips(self.events, attendance, weather)
        self._arrivals, self._departures, self._event_rows = surges(self.events, trips_arr, trips_dep, year, S, self.share * self.demand_scale)
        if totals is not None:
            self._real_level(totals, zone_profile, zone_hourly, tilt, notes)
        parts = [f"hourly-totals {self.hourly_totals_source}"] if totals is not None else []
        parts += [f"zone-od {Path(zone_profile.source).name}"] if zone_profile is not None else []
        parts += [f"zone-hourly {zone_hourly.source}"] if totals is not None and zone_hourly is not None else []
        self.demand_source = f"{' + '.join(parts or ['synthetic profile'])}, share {self.share:g}"
        self._base.setflags(write=False)
        self._rate = self._base + self._arrivals @ self._origin + self._departures
        self._rate.setflags(write=False)
        self._counts: np.ndarray | None = None

    def _real_level(self, totals: np.ndarray, zone_profile: "ZoneProfile | None", zone_hourly: "ZoneHourly | None",
                    tilt: np.ndarray, notes: list[str]) -> None:
        """Base demand at each hour's real total (see :mod:`city.demand.real_level`), replacing the profile's."""
        kinds = day_kinds(self.year, self.holidays)
        by_type = zone_hourly.by_day_type(self.city.sector_ids, self.holidays)[0] if zone_hourly is not None else None
        synthetic = self.intensity[None, :] * (1.0 + tilt[None, :] * TILT[:, None])
        split = sector_split(zone_profile.rate() if zone_profile is not None else None, by_type, synthetic)
        events = (self._arrivals.sum(axis=1) + self._departures.sum(axis=1)) / self.demand_scale
        base, floored = real_base(totals, self.share, split, kinds, events, day_kinds(self.year, frozenset()))
        self._base = base * self.demand_scale
        self._real_totals = totals
        by = ("zone profile " + Path(zone_profile.source).name) if zone_profile is not None else None
        weekend = f"its weekday mean × weekend ratios of {zone_hourly.source}" if zone_hourly is not None and by else \
            (f"zone counts {zone_hourly.source}" if zone_hourly is not None else "the synthetic sector intensity")
        self.base_source = (f"real hourly totals {self.hourly_totals_source} × share {self.share:g} less the usual event trips, split by "
                            + (f"{by} (weekends and holidays: {weekend})" if by else weekend))
        notes[:] = [n for n in notes if not n.startswith("base demand:")]
        notes.append(f"base demand: {self.base_source}")
        if floored:
            notes.append(f"base demand: {floored} hours kept at {BASE_FLOOR:g} of their real total (usual event trips above the rest)")

    # ------------------------------------------------------------ rates
    def real_level(self) -> np.ndarray | None:
        """``(hours_in_year,)`` real total × share × demand scale of every hour, or ``None`` without hourly totals."""
        return None if self._real_totals is None else self._real_totals * self.share * self.demand_scale

    def base_rate(self) -> np.ndarray:
        """``(hours_in_year, S)`` expected requests without event surges."""
        return self._base

    def event_rate(self) -> np.ndarray:
        """``(hours_in_year, S)`` expected event requests (arrival pickups and departures) per pickup sector."""
        return self._rate - self._base

    def expected_rate(self) -> np.ndarray:
        return self._rate

    def hourly_counts(self) -> np.ndarray:
        """Poisson draws of :meth:`expected_rate`, from the world seed (computed once)."""
        if self._counts is None:
            counts = np.random.default_rng([self.seed, self.year, 15]).poisson(self._rate)
            counts.setflags(write=False)
            self._counts = counts
        return self._counts

    # ------------------------------------------------------------ where trips go
    def _base_beta(self, h: int) -> np.ndarray:
        """β of the base demand at hour row ``h``: the zone profile's weekday-hour, or the gravity model."""
        if self._profile_beta is None:
            return self._static_beta
        kind = day_kind(self.when(h).date(), self.holidays)
        beta = self._profile_beta[kind, h % 24] if kind < 5 else self._profile_beta[:, h % 24].mean(axis=0)
        return beta

    def _event_nodes(self, h: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Venue node and sector, arrival and departure trips of the event-hours of row ``h``."""
        ev, hours, trips_arr, trips_dep = self._event_rows
        lo, hi = np.searchsorted(hours, [h, h + 1])
        idx = ev[lo:hi]
        node = np.array([self.events[i].node for i in idx], dtype=np.int64)
        sector = np.array([self.events[i].sector for i in idx], dtype=np.int64)
        return node, sector, trips_arr[lo:hi], trips_dep[lo:hi]

    def od_matrix(self, when: dt.datetime) -> np.ndarray:
        """β of the hour: base flows, arrivals ending in venue sectors and departures heading home."""
        h = self.hour_index(when)
        beta = self._base_beta(h)
        flow = self._base[h][:, None] * beta + self._origin.T * self._arrivals[h][None, :] + self._departures[h][:, None] * self._origin
        rows = flow.sum(axis=1, keepdims=True)
        return np.where(rows > 0, flow / np.where(rows > 0, rows, 1.0), beta)

    def pickup_dist(self, when: dt.datetime) -> np.ndarray:
        """ρ of the hour: occupancy-weighted, plus the departure pickups at the venues."""
        h = self.hour_index(when)
        occ = self._assignment(when)[0]
        node, sector, _, dep = self._event_nodes(h)
        if not np.any(dep > 0):
            return occ.copy()
        spread = self._base[h] + self._arrivals[h] @ self._origin
        mass = occ * spread[self.city.node_sector]
        np.add.at(mass, node, dep)
        return self._per_sector(mass, occ)

    def dropoff_dist(self, when: dt.datetime) -> np.ndarray:
        """δ of the hour: occupancy-weighted, plus the arrival drop-offs at the venues."""
        h = self.hour_index(when)
        occ = self._assignment(when)[0]
        node, sector, arr, _ = self._event_nodes(h)
        if not np.any(arr > 0):
            return occ.copy()
        inflow = self._base[h] @ self._base_beta(h) + self._departures[h] @ self._origin
        mass = occ * inflow[self.city.node_sector]
        np.add.at(mass, node, arr)
        return self._per_sector(mass, occ)

    def _per_sector(self, mass: np.ndarray, fallback: np.ndarray) -> np.ndarray:
        total = np.bincount(self.city.node_sector, weights=mass, minlength=self.city.n_sectors)[self.city.node_sector]
        return np.where(total > 0, mass / np.where(total > 0, total, 1.0), fallback)

    def _hour_trips(self, h: int, rng: np.random.Generator) -> HourTrips:
        """Each sector's realised count split by multinomial over base, arrival and departure components."""
        S = self.city.n_sectors
        counts = self.hourly_counts()[h]
        node, sector, arr, dep = self._event_nodes(h)
        K = len(node)
        rates = np.zeros((S, 1 + 2 * K))
        rates[:, 0] = self._base[h]
        rates[:, 1 : 1 + K] = self._origin[sector].T * arr[None, :]
        rates[sector, 1 + K + np.arange(K)] = dep
        total = rates.sum(axis=1, keepdims=True)
        probs = np.where(total > 0, rates / np.where(total > 0, total, 1.0), np.eye(1, 1 + 2 * K))
        split = rng.multinomial(counts, probs)
        comp_sector, comp = np.nonzero(split)
        reps = split[comp_sector, comp]
        ps = np.repeat(comp_sector, reps)
        c = np.repeat(comp, reps)
        pick_node = np.full(len(ps), -1, dtype=np.int64)
        drop_node = np.full(len(ps), -1, dtype=np.int64)
        ds = np.empty(len(ps), dtype=np.int64)
        k = c - 1
        is_arr = (c >= 1) & (c <= K)
        is_dep = c > K
        ds[is_arr] = sector[k[is_arr]]
        drop_node[is_arr] = node[k[is_arr]]
        pick_node[is_dep] = node[k[is_dep] - K]
        free = ~is_arr
        # Base trips follow the hour's base β; departures head back where the arrivals came from.
        rows = np.where(is_dep, 0, 1)[free]
        cum_base = np.cumsum(self._base_beta(h), axis=1)
        cum_home = np.cumsum(self._origin, axis=1)
        src = ps[free]
        cum = np.where(rows[:, None] == 1, cum_base[src], cum_home[src])
        u = rng.random(len(src)) * cum[:, -1]
        ds[free] = np.minimum((cum <= u[:, None]).sum(axis=1), S - 1)
        minute = rng.integers(0, 60, size=len(ps))
        return HourTrips(ps, ds, minute, pick_node, drop_node)

    def event_titles_by_sector(self, when: dt.datetime) -> list[list[str]]:
        """Per sector, titles of the events whose arrival pickups or departures add at least half a trip that hour."""
        h = self.hour_index(when)
        ev, hours, trips_arr, trips_dep = self._event_rows
        lo, hi = np.searchsorted(hours, [h, h + 1])
        share: dict[int, list[tuple[float, str]]] = {}
        for i in range(lo, hi):
            e = self.events[ev[i]]
            add = trips_arr[i] * self._origin[e.sector]
            add[e.sector] += trips_dep[i]
            for s in np.flatnonzero(add >= 0.5):
                share.setdefault(int(s), []).append((-add[s], e.title))
        return [[t for _, t in sorted(share.get(s, []))] for s in range(self.city.n_sectors)]

    def beta_from_months(self, months: tuple[int, ...]) -> np.ndarray:
        """β of the expected flows summed over every hour of ``months`` (rows sum to one)."""
        first = dt.datetime(self.year, 1, 1)
        flow = np.zeros((self.city.n_sectors,) * 2)
        for h in range(self.n_hours):
            if (first + dt.timedelta(hours=h)).month in months:
                flow += self.od_matrix(first + dt.timedelta(hours=h)) * self._rate[h][:, None]
        rows = flow.sum(axis=1, keepdims=True)
        return np.where(rows > 0, flow / np.where(rows > 0, rows, 1.0), 1.0 / self.city.n_sectors)


#: The world's usual name in calling code: one signature, the class's.
synthetic_world = SyntheticWorld
