"""Scenarios by name: the city plus its demand world, built once and cached on disk."""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

from city.errors import ConfigError
from city.graph import City

SCENARIOS = ("synthetic", "nyc")
#: Environment variable with the fleet's share of real zone-profile trips (``--share``), so worker
#: and agent processes build the same world as the command that started them.
SHARE_ENV = "SURGE_SHARE"
#: The real zone-to-zone trip profile under a data directory (base demand of ``nyc``).
ZONE_PROFILE = Path("nyc") / "trips" / "manhattan_zone_od_15min_2018.csv"
#: Bump when a change to a city builder changes its output, so caches rebuild.
CITY_VERSION = "1"


@dataclass(frozen=True)
class Scenario:
    name: str
    city: City
    world: object
    data_dir: Path | None


def cache_dir() -> Path:
    """Where built artefacts live: ``$SURGE_CACHE`` or ``~/.cache/surge``."""
    path = Path(os.environ.get("SURGE_CACHE", Path.home() / ".cache" / "surge"))
    path.mkdir(parents=True, exist_ok=True)
    return path


def check_scenario(name: str, data_dir: Path | str | None) -> Path | None:
    """Validate a scenario name and its data directory; raise :class:`ConfigError` with one line."""
    if name not in SCENARIOS:
        raise ConfigError(f"unknown scenario {name!r}; choose from {', '.join(SCENARIOS)}")
    if name == "nyc":
        if data_dir is None:
            raise ConfigError("scenario 'nyc' needs --data DIR (a directory laid out like shared/data)")
        data_dir = Path(data_dir)
        if not data_dir.is_dir():
            raise ConfigError(f"data directory {data_dir} does not exist")
        return data_dir
    return Path(data_dir) if data_dir is not None else None


def _nyc_inputs(data_dir: Path) -> list[Path]:
    return sorted(p for p in (data_dir / "nyc").rglob("*") if p.is_file() and p.suffix in {".csv", ".geojson", ".shp", ".graphml"})


def load_city(name: str, data_dir: Path | str | None = None, *, use_cache: bool = True) -> City:
    """Build (or load from cache) the street graph of a scenario."""
    data_dir = check_scenario(name, data_dir)
    key = hashlib.sha256(f"{name}|{CITY_VERSION}".encode())
    if name == "nyc":
        assert data_dir is not None
        for p in _nyc_inputs(data_dir):
            st = p.stat()
            key.update(f"{p.resolve()}|{st.st_size}|{st.st_mtime_ns}".encode())
    path = cache_dir() / f"city-{name}-{key.hexdigest()[:16]}.npz"
    if use_cache and path.exists():
        return City.load(path)
    if name == "synthetic":
        from city.synthetic import synthetic_city

        city = synthetic_city()
    else:
        from city.nyc import load_nyc_city

        assert data_dir is not None
        city = load_nyc_city(data_dir)
    if use_cache:
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        city.save(tmp)
        os.replace(tmp, path)
    return city


def trip_files(data_dir: Path) -> list[Path]:
    """A user's TLC High-Volume FHV parquet files, if any, under ``nyc/trips``."""
    return sorted((data_dir / "nyc" / "trips").glob("fhvhv_tripdata_*.parquet"))


def load_zone_profile(path: Path, city: City):  # noqa: ANN201 - city.trips.ZoneProfile, imported lazily
    """:func:`city.trips.read_zone_profile`, cached on disk by file and city (the CSV takes seconds to parse)."""
    import warnings

    import numpy as np

    from city.trips import ZoneProfile, read_zone_profile

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


def load_scenario(name: str, data_dir: Path | str | None = None, *, year: int = 2022, seed: int = 0, share: float | None = None) -> Scenario:
    """The city and its demand world.

    ``synthetic`` generates everything.  ``nyc`` reads the real map, LGA hourly
    weather and points of interest from ``data_dir``; its demand is replayed
    from TLC HV-FHV trip records when ``nyc/trips/fhvhv_tripdata_*.parquet``
    files are there (with the permitted-events calendar).  Otherwise its base
    demand and β come from the real zone profile (:data:`ZONE_PROFILE`) when
    present, with synthetic weather effects, holidays and event surges on top;
    without the file they are synthesised.  ``share`` (default ``$SURGE_SHARE``,
    else :data:`city.demand.profile.FLEET_SHARE`) is the fleet's share of the real
    market on the synthesised maps: it scales base demand and event trips.
    """
    data_dir = check_scenario(name, data_dir)
    city = load_city(name, data_dir)
    from city.demand import RecordedWorld, synthetic_world
    from city.demand.profile import FLEET_SHARE

    share = share if share is not None else share_from_env() or FLEET_SHARE
    if name == "synthetic":
        return Scenario(name=name, city=city, world=synthetic_world(city, year=year, seed=seed, share=share), data_dir=data_dir)
    from city.poi import read_poi_csv
    from city.weather import read_weather_csv

    assert data_dir is not None
    weather = read_weather_csv(data_dir / "nyc" / "weather" / "airports_hourly_2022.csv", station="LGA", year=year)
    pois = read_poi_csv(data_dir / "nyc" / "poi" / "nyc_points_of_interest.csv")
    trips = trip_files(data_dir)
    if trips:
        from city.events import read_permitted_events
        from city.trips import read_fhvhv

        calendar = data_dir / "nyc" / "events" / "nyc_permitted_events_2022.csv"
        events = read_permitted_events(calendar, city) if calendar.exists() else []
        world = RecordedWorld(city, read_fhvhv(trips, city), year=year, seed=seed, events=events, weather=weather, pois=pois)
    else:
        profile = None
        if (data_dir / ZONE_PROFILE).exists():
            profile = load_zone_profile(data_dir / ZONE_PROFILE, city)
        world = synthetic_world(city, year=year, seed=seed, weather=weather, pois=pois, zone_profile=profile, share=share)
    return Scenario(name=name, city=city, world=world, data_dir=data_dir)
