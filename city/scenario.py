"""Scenarios by name or file: the city plus its demand world, the city built once and cached on disk.

``synthetic`` is embedded.  Every other scenario is a scenario file
(:mod:`city.io.scenario_file`): ``nyc`` and ``manhattan`` are files shipped in
``city/scenarios/`` that point into a data directory (``--data``), and any
``PATH.toml`` is a user's own city.
"""

from __future__ import annotations

import hashlib
import os
import warnings
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from city.errors import ConfigError
from city.graph import City
from city.io.scenario_file import ScenarioSpec, read_scenario_file

#: Scenario files shipped in the package, by name.
SHIPPED = ("nyc", "manhattan")
SCENARIOS = ("synthetic", *SHIPPED)
#: Environment variable with the fleet's share of real demand (``--share``), so worker
#: and agent processes build the same world as the command that started them.
SHARE_ENV = "SURGE_SHARE"
#: Bump when a change to a city builder changes its output, so caches rebuild.
CITY_VERSION = "4"


@dataclass(frozen=True)
class Scenario:
    """A city, its demand world, and the scenario file it came from (``None`` for ``synthetic``).

    ``schedules`` are the file's occupancy schedules (the shape of
    :data:`city.io.occupancy.SCHEDULES`), ``None`` for the built-in ones.
    """

    name: str
    city: City
    world: object
    data_dir: Path | None
    spec: ScenarioSpec | None = None
    schedules: dict | None = None


def cache_root() -> Path:
    """The surge cache root, not created: ``$SURGE_CACHE``, else the platform's user cache folder (``~/.cache/surge`` on Linux)."""
    env = os.environ.get("SURGE_CACHE")
    if env:
        return Path(env).expanduser()
    from platformdirs import user_cache_path

    return user_cache_path("surge", appauthor=False)


def cache_dir() -> Path:
    """Where built artefacts live (:func:`cache_root`), created if need be."""
    path = cache_root()
    path.mkdir(parents=True, exist_ok=True)
    return path


def scenario_path(name: str) -> Path | None:
    """The scenario file ``name`` stands for: a shipped one, a ``.toml`` path, or ``None`` for ``synthetic``."""
    if name == "synthetic":
        return None
    if name in SHIPPED:
        return Path(str(resources.files("city") / "scenarios" / f"{name}.toml"))
    if name.endswith(".toml") or os.sep in name or Path(name).is_file():
        return Path(name)
    raise ConfigError(f"unknown scenario {name!r}; choose from {', '.join(SCENARIOS)} or give a scenario .toml file")


def scenario_spec(name: str, data_dir: Path | str | None = None, *, validate: bool = True) -> ScenarioSpec | None:
    """The parsed, checked scenario file of ``name`` (``None`` for ``synthetic``); one-line errors.

    ``validate=False`` skips the checks of names (see :func:`read_scenario_file`).
    """
    path = scenario_path(name)
    if data_dir is not None and not Path(data_dir).is_dir():
        raise ConfigError(f"data directory {data_dir} does not exist")
    if path is None:
        return None
    if name in SHIPPED and data_dir is None:
        raise ConfigError(f"scenario {name!r} needs --data DIR (a directory laid out like shared/data)")
    return read_scenario_file(path, data_dir, validate=validate)


def scenario_timezone(name: str, data_dir: Path | str | None = None) -> str:
    """The zone a scenario's local times are in, for every events file read for it (``synthetic``: New York's)."""
    from city.io.events import DEFAULT_TZ

    spec = scenario_spec(name, data_dir, validate=False)
    return spec.timezone if spec is not None else DEFAULT_TZ


def check_scenario(name: str, data_dir: Path | str | None) -> Path | None:
    """Validate a scenario (its whole file, if any) and its data directory; the data directory it uses.

    The synthetic scenario reads no files: a ``--data`` given with it is
    unused, and a warning says so, since a user who gave it most likely
    meant a real map.
    """
    spec = scenario_spec(name, data_dir)
    if spec is not None:
        return spec.data_dir
    if data_dir is not None:
        warnings.warn(f"the synthetic scenario reads no data: --data {data_dir} is not used "
                      f"(give --scenario {' or '.join(SHIPPED)} or a scenario file to use it)", stacklevel=2)
    return None


def load_city(name: str, data_dir: Path | str | None = None, *, use_cache: bool = True, mmap: bool = False) -> City:
    """Build (or load from cache) the street graph of a scenario; with ``mmap``, mapped from the cache file (see :meth:`City.load`).

    ``mmap`` is how agents load the city: they skip the checks of names in the
    scenario file, which the command that started the run has made.
    """
    spec = scenario_spec(name, data_dir, validate=not mmap)
    key = hashlib.sha256(f"{name if spec is None else spec.name}|{CITY_VERSION}".encode())
    if spec is not None:
        key.update(repr((spec.streets.crs, spec.zones.id_field, spec.zones.name_field, spec.zones.select, spec.zones.missing)).encode())
        for p in spec.city_inputs():
            st = p.stat()
            key.update(f"{p.resolve()}|{st.st_size}|{st.st_mtime_ns}".encode())
    label = "synthetic" if spec is None else spec.name
    path = cache_dir() / f"city-{label}-{key.hexdigest()[:16]}.npz"
    if use_cache and path.exists():
        return City.load(path, mmap=mmap)
    if spec is None:
        from city.synthetic import synthetic_city

        city = synthetic_city()
    else:
        city = build_city(spec)
    if use_cache:
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        city.save(tmp)
        os.replace(tmp, path)
        if mmap:
            return City.load(path, mmap=True)
    return city


def build_city(spec: ScenarioSpec) -> City:
    """The street graph of a scenario file: its streets clipped to its zones, one sector per zone."""
    from city.io.street_map import (
        build_zone_map,
        check_zone_polygons,
        read_zone_file,
        zone_ids_in_group,
        zone_names_in_groups,
    )

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        streets = read_streets(spec)
    notes = [str(w.message) for w in caught]
    for note in notes:
        warnings.warn(note, stacklevel=2)
    z = spec.zones
    polygons, names = read_zone_file(z.file, z.id_field, z.name_field)
    how = z.select[0]
    if how == "all":
        ids = sorted(polygons)
    elif how == "ids":
        ids = list(z.select[1])
    else:
        assert z.groups is not None
        ids = zone_ids_in_group(z.groups, "group" if how == "group" else "Borough", z.select[1])
    known = zone_names_in_groups(z.groups) if z.groups is not None else {}
    if z.missing == "skip":
        skipped = [i for i in ids if i not in polygons]
        if skipped:
            note = f"{spec.path}: zones.missing = \"skip\": left out zone(s) {', '.join(map(str, skipped))}, which have no polygon in {z.file.name}"
            notes.append(note)
            warnings.warn(note, stacklevel=2)
        ids = [i for i in ids if i in polygons]
    check_zone_polygons(ids, polygons, names, z.file, known=known, where=f"{spec.path}: zones")
    return build_zone_map(spec.name, streets, polygons, names, ids, zone_src=z.file.name, notes=notes,
                          info={"scenario_file": str(spec.path), "zones": list(z.select[:1]) + [str(v) for v in z.select[1:]]})


def read_streets(spec: ScenarioSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    """``(osmid, xy, u, v, length, source)`` of the scenario's street network, ``xy`` taken to lon/lat by pyproj."""
    from city.io.street_map import read_graphml, read_street_csv

    s = spec.streets
    if s.graphml is not None:
        osmid, xy, u, v, length = read_graphml(s.graphml)
        source = s.graphml.name
    else:
        assert s.nodes is not None and s.edges is not None
        osmid, xy, u, v, length = read_street_csv(s.nodes, s.edges)
        source = s.nodes.name
    from pyproj import CRS, Transformer

    crs = CRS.from_user_input(s.crs)
    if not crs.equals(CRS.from_epsg(4326), ignore_axis_order=True):
        to_lonlat = Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
        xy = np.column_stack(to_lonlat.transform(xy[:, 0], xy[:, 1]))
    return osmid, xy, u, v, length, source
def load_zone_profile(path: Path, city: City):
    """:func:`city.io.trips.read_zone_profile`, cached on disk by file and city (the CSV takes seconds to parse)."""
    from city.io.trips import ZoneProfile, read_zone_profile

    st = path.stat()
    key = hashlib.sha256(f"{path.resolve()}|{st.st_size}|{st.st_mtime_ns}|{CITY_VERSION}|{city.sector_ids.tolist()}".encode())
    cached = cache_dir() / f"zone-profile-{key.hexdigest()[:16]}.npz"
    if cached.exists():
        z = np.load(cached)
        profile = ZoneProfile(z["trips"], z["business_days"], tuple(int(s) for s in z["filled"]), int(z["n_rows"]), int(z["n_outside"]), str(path))
        if profile.filled:
            zones = ", ".join(f"{city.sector_ids[s]} ({city.sector_names[s]})" for s in profile.filled)
            warnings.warn(f"{path}: no trips from zone {zones}; filled from its adjacent zones per intersection", stacklevel=2)
        return profile
    profile = read_zone_profile(path, city)
    tmp = cached.with_suffix(f".{os.getpid()}.tmp.npz")
    np.savez(tmp, trips=profile.trips, business_days=profile.business_days, filled=np.array(profile.filled, dtype=np.int64),
             n_rows=profile.n_rows, n_outside=profile.n_outside)
    os.replace(tmp, cached)
    return profile


def share_from_env() -> float | None:
    """The ``--share`` a parent command exported, if any."""
    text = os.environ.get(SHARE_ENV)
    if not text:
        return None
    try:
        share = float(text)
    except ValueError:
        raise ConfigError(f"{SHARE_ENV}={text!r} is not a number") from None
    if not 0 < share <= 1:
        raise ConfigError(f"{SHARE_ENV}={share} must be in (0, 1]")
    return share


def load_scenario(name: str, data_dir: Path | str | None = None, *, year: int | None = None, seed: int = 0, share: float | None = None) -> Scenario:
    """The city and its demand world.

    ``synthetic`` generates everything.  A scenario file's world replays its
    trip records (``[[trips]] kind = "fhvhv"``) with its events when it has
    them.  Otherwise it is synthesised on the real map: with real hourly
    trip totals (``kind = "hourly-totals"``) its base demand is each hour's
    real level, split over sectors by its zone-OD profile and zone-hourly
    counts (:mod:`city.demand.real_level`), with event surges above the usual
    event level; without them its base demand and β come from a zone-OD
    profile (``kind = "zone-od"``, e.g. the real Manhattan profile of ``nyc``)
    when it names one, with synthetic weather effects, holidays and event
    surges on top; weather and points of interest come from its files when it
    names them.  ``share`` (default
    ``$SURGE_SHARE``) overrides the file's share of its trips; on a
    synthesised world it scales base demand and event trips (default
    :data:`city.demand.profile.FLEET_SHARE`; with hourly totals,
    :func:`city.demand.real_level.default_share`).  ``year`` is the demand
    world's (commands pass their dates' year); by default the file's
    ``year`` key, else 2022.
    """
    spec = scenario_spec(name, data_dir)
    year = year if year is not None else (spec.year if spec is not None else 2022)
    city = load_city(name, data_dir)
    from city.demand import synthetic_world
    from city.demand.profile import FLEET_SHARE

    share = share if share is not None else share_from_env()
    if spec is None:
        world = synthetic_world(city, year=year, seed=seed, share=share or FLEET_SHARE)
        return Scenario(name=name, city=city, world=world, data_dir=None)
    world = build_world(spec, city, year=year, seed=seed, share=share)
    return Scenario(name=name, city=city, world=world, data_dir=spec.data_dir, spec=spec, schedules=world.schedules)


def build_world(spec: ScenarioSpec, city: City, *, year: int, seed: int = 0, share: float | None = None) -> object:
    """The demand world of a scenario file on its city.

    The first ``fhvhv`` or ``zone-od`` entry with files is used, with the
    first ``hourly-totals`` and ``zone-hourly`` entries with files (trip
    records are replayed as they are, without them); ``share`` (a command's
    ``--share``) overrides the entries' ``share``.  The file's ``[holidays]``
    and ``[occupancy]`` schedules go into the world.
    """
    from city.demand import RecordedWorld, synthetic_world
    from city.demand.naming import naming_for
    from city.demand.profile import FLEET_SHARE

    calendar = {"holidays": (spec.holidays["country"], spec.holidays["subdiv"]), "schedules": None}
    naming = naming_for(spec.event_names, spec.name)
    if spec.occupancy is not None:
        from city.io.occupancy import read_occupancy_csv

        calendar["schedules"] = read_occupancy_csv(spec.occupancy)
    weather = pois = None
    if spec.weather is not None:
        from city.io.weather import read_weather_csv

        w = spec.weather
        weather = read_weather_csv(w.file, station=w.station or "LGA", year=year, columns=w.columns, timezone=spec.timezone)
    if spec.pois is not None:
        from city.io.poi import read_poi_csv

        pois = read_poi_csv(spec.pois.file, borough=spec.pois.borough, types=spec.pois.types)
    trips = next((t for t in spec.trips if t.files and t.kind in ("fhvhv", "zone-od")), None)
    hourly = next((t for t in spec.trips if t.files and t.kind == "hourly-totals"), None)
    if hourly is not None and (trips is None or trips.kind == "zone-od"):
        from city.io.hourly_totals import read_hourly_totals
        from city.io.zone_hourly import read_zone_hourly

        zonal = next((t for t in spec.trips if t.files and t.kind == "zone-hourly"), None)
        return synthetic_world(
            city, year=year, seed=seed, weather=weather, pois=pois, share=share or hourly.share,
            zone_profile=load_zone_profile(trips.files[0], city) if trips is not None else None,
            hourly_totals=read_hourly_totals(hourly.files[0], columns=hourly.columns),
            zone_hourly=read_zone_hourly(zonal.files[0], columns=zonal.columns, timezone=spec.timezone) if zonal is not None else None,
            naming=naming,
            **calendar)
    if trips is not None and trips.kind == "zone-od":
        profile = load_zone_profile(trips.files[0], city)
        return synthetic_world(city, year=year, seed=seed, weather=weather, pois=pois, zone_profile=profile,
                               share=share or trips.share or FLEET_SHARE, naming=naming, **calendar)
    if trips is not None:
        from city.io.trips import read_fhvhv

        table = read_fhvhv(list(trips.files), city)
        keep = share if share is not None else trips.share
        if keep is not None and keep < 1.0:
            table = sample_trips(table, keep, seed)
        return RecordedWorld(city, table, year=year, seed=seed, events=read_scenario_events(spec, city), weather=weather, pois=pois,
                             **calendar)
    return synthetic_world(city, year=year, seed=seed, weather=weather, pois=pois, share=share or FLEET_SHARE, naming=naming, **calendar)


def sample_trips(table, share: float, seed: int):
    """A seeded ``share`` of the trips of a :class:`city.io.trips.TripTable` (each kept with probability ``share``)."""
    from city.io.trips import TripTable

    keep = np.random.default_rng([seed, 14]).random(len(table)) < share
    return TripTable(request_time=table.request_time[keep], pickup_sector=table.pickup_sector[keep],
                     dropoff_sector=table.dropoff_sector[keep], n_read=table.n_read, n_dropped=table.n_dropped + int((~keep).sum()))


def read_scenario_events(spec: ScenarioSpec, city: City) -> list:
    """The events of a scenario file placed on ``city`` (an empty list without ``[events]``)."""
    ev = spec.events
    if ev is None:
        return []
    from city.io.events import read_events, read_permitted_events

    if ev.kind == "permitted":
        return read_permitted_events(ev.file, city, borough=ev.borough)
    return read_events(ev.file, city, ev.reviews, tz=spec.timezone)
