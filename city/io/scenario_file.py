"""Scenario files: a city and its demand inputs described in TOML, read with :mod:`tomllib`.

A scenario file names the street network, the zones that become sectors,
the timezone and holidays, and optionally weather, points of interest,
occupancy schedules, trips, and events with reviews.  Paths are relative to
the file's folder; a path that starts with ``${data}/`` is relative to the
data directory instead (``--data DIR``, or the file's own ``data`` key), so
one file serves every copy of a data set.  See ``city/scenarios/*.toml`` for
the shipped ``nyc`` and ``manhattan`` files.

Every problem is one :class:`~city.errors.ConfigError` line naming the file,
the key and what is wrong: a missing or unknown key, a value of the wrong
type, or a file that does not exist.  The files themselves are read later,
by the readers of :mod:`city`, whose errors name file and row.
"""

from __future__ import annotations

import glob
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from city.errors import ConfigError
from city.io.occupancy import LOCALE_TYPES

DATA_PREFIX = "${data}/"
ZONE_MISSING = ("error", "skip")
TRIP_KINDS = ("fhvhv", "zone-od")
EVENT_KINDS = ("permitted", "listing")
WEATHER_COLUMNS = ("time", "temp_f", "precip_in", "wind_mph")


@dataclass(frozen=True)
class StreetsSpec:
    """An OSMnx node/edge CSV pair or a GraphML file; ``crs`` is the node coordinates' system (pyproj string)."""

    nodes: Path | None
    edges: Path | None
    graphml: Path | None
    crs: str


@dataclass(frozen=True)
class ZonesSpec:
    """Zone polygons (GeoJSON or shapefile) and which of them become sectors.

    ``select`` is ``("all",)``, ``("ids", (…))``, ``("group", name)`` or
    ``("borough", name)``; the last two read ``groups``.
    """

    file: Path
    id_field: str
    name_field: str
    groups: Path | None
    select: tuple
    missing: str


@dataclass(frozen=True)
class WeatherSpec:
    file: Path
    station: str | None
    columns: dict[str, str] | None


@dataclass(frozen=True)
class PoiSpec:
    """Points of interest; ``types`` maps the file's ``kind`` values to locale types (or ``other``)."""

    file: Path
    borough: int | None
    types: dict[str, str] | None


@dataclass(frozen=True)
class TripsSpec:
    """Trip records (``fhvhv`` parquet files) or a zone-OD profile, and the fleet's ``share`` of them.

    ``share`` ``None`` leaves it to the world (all recorded trips; the
    world's default share of a profile).  ``optional``: no matching file is
    not an error (the next entry, or a synthesised demand, is used).
    """

    kind: str
    files: tuple[Path, ...]
    share: float | None
    optional: bool


@dataclass(frozen=True)
class EventsSpec:
    file: Path
    kind: str
    borough: str
    reviews: Path | None


@dataclass(frozen=True)
class ScenarioSpec:
    """A parsed, checked scenario file; every path absolute."""

    name: str
    path: Path
    data_dir: Path | None
    timezone: str
    holidays: dict[str, str | None]
    streets: StreetsSpec
    zones: ZonesSpec
    weather: WeatherSpec | None = None
    pois: PoiSpec | None = None
    occupancy: Path | None = None
    trips: tuple[TripsSpec, ...] = ()
    events: EventsSpec | None = None

    def city_inputs(self) -> list[Path]:
        """The files the street graph is built from (for the city cache key)."""
        z = self.zones
        out = [p for p in (self.streets.nodes, self.streets.edges, self.streets.graphml, z.file, z.groups) if p is not None]
        if z.file.suffix.lower() == ".shp":
            out.append(z.file.with_suffix(".prj"))
        return out


class _Reader:
    """Walks one TOML table, checking keys and types, and resolving paths; errors name file and key."""

    def __init__(self, path: Path, data_dir: Path | None, validate: bool = True) -> None:
        self.path = path
        self.data_dir = data_dir
        #: Check names against pyproj's and the holidays package's lists (each import costs a process megabytes).
        self.validate = validate

    def fail(self, key: str, problem: str) -> ConfigError:
        return ConfigError(f"{self.path}: {key}: {problem}")

    def table(self, doc: dict, key: str, known: tuple[str, ...], *, required: bool = False) -> dict | None:
        value = doc.get(key.rpartition(".")[2])
        if value is None:
            if required:
                raise self.fail(key, f"missing; the scenario needs a [{key}] table")
            return None
        if not isinstance(value, dict):
            raise self.fail(key, f"expected a table ([{key}]), got {type(value).__name__}")
        self.known(value, key, known)
        return value

    def known(self, table: dict, prefix: str, known: tuple[str, ...]) -> None:
        for k in table:
            if k not in known:
                raise self.fail(f"{prefix}.{k}" if prefix else k, f"unknown key; expected one of {', '.join(known)}")

    def get(self, table: dict, prefix: str, key: str, kind: type | tuple[type, ...], *, required: bool = False, default: Any = None) -> Any:
        full = f"{prefix}.{key}" if prefix else key
        if key not in table:
            if required:
                raise self.fail(full, "missing")
            return default
        value = table[key]
        if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
            names = " or ".join(t.__name__ for t in (kind if isinstance(kind, tuple) else (kind,)))
            raise self.fail(full, f"expected {names}, got {value!r}")
        return value

    def file(self, table: dict, prefix: str, key: str, *, required: bool = False) -> Path | None:
        text = self.get(table, prefix, key, str, required=required)
        if text is None:
            return None
        path = self.resolve(f"{prefix}.{key}", text)
        if not path.is_file():
            raise self.fail(f"{prefix}.{key}", f"file {path} does not exist")
        return path

    def resolve(self, key: str, text: str) -> Path:
        if text.startswith(DATA_PREFIX):
            if self.data_dir is None:
                raise self.fail(key, f"{text!r} is in the data directory; give it with --data DIR (or a 'data' key)")
            return self.data_dir / text[len(DATA_PREFIX):]
        path = Path(text).expanduser()
        return path if path.is_absolute() else self.path.parent / path


def read_scenario_file(path: Path | str, data_dir: Path | str | None = None, *, validate: bool = True) -> ScenarioSpec:
    """Parse and check a scenario file; ``data_dir`` (``--data``) overrides the file's ``data`` key.

    ``validate=False`` leaves out the checks of the coordinate system and the
    holiday calendar by name, for a process (an agent) that only maps a city
    already built from the file.

    Raises
    ------
    ConfigError
        One line naming the file, the key and the problem.
    """
    path = Path(path).resolve() if Path(path).exists() else Path(path)
    if not path.is_file():
        raise ConfigError(f"scenario file {path} does not exist")
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: not a TOML file ({exc})") from None
    r = _Reader(path, None, validate)
    r.known(doc, "", ("name", "data", "timezone", "holidays", "streets", "zones", "weather", "pois", "occupancy", "trips", "events"))
    if data_dir is not None:
        r.data_dir = Path(data_dir)
    elif "data" in doc:
        r.data_dir = r.resolve("data", r.get(doc, "", "data", str))
    if r.data_dir is not None and not r.data_dir.is_dir():
        origin = "--data" if data_dir is not None else f"{path}: data"
        raise ConfigError(f"{origin}: data directory {r.data_dir} does not exist")

    name = r.get(doc, "", "name", str, default=path.stem)
    timezone = r.get(doc, "", "timezone", str, required=True)
    try:
        ZoneInfo(timezone)
    except (ZoneInfoNotFoundError, ValueError):
        raise r.fail("timezone", f"{timezone!r} is not an IANA timezone such as America/New_York") from None
    holidays = {"country": "US", "subdiv": None}
    if (h := r.table(doc, "holidays", ("country", "subdiv"))) is not None:
        holidays = {"country": r.get(h, "holidays", "country", str, required=True), "subdiv": r.get(h, "holidays", "subdiv", str)}
    if h is not None and validate:
        from city.calendar import holidays_for

        try:
            holidays_for(2022, holidays["country"], holidays["subdiv"])
        except ConfigError as exc:
            raise r.fail("holidays", str(exc).removeprefix("holidays: ")) from None

    return ScenarioSpec(
        name=name, path=path, data_dir=r.data_dir, timezone=timezone, holidays=holidays,
        streets=_streets(r, doc), zones=_zones(r, doc), weather=_weather(r, doc), pois=_pois(r, doc),
        occupancy=_occupancy(r, doc), trips=_trips(r, doc), events=_events(r, doc),
    )


def _streets(r: _Reader, doc: dict) -> StreetsSpec:
    t = r.table(doc, "streets", ("nodes", "edges", "graphml", "crs"), required=True)
    assert t is not None
    nodes, edges, graphml = (r.file(t, "streets", k) for k in ("nodes", "edges", "graphml"))
    if graphml is not None and (nodes or edges):
        raise r.fail("streets", "give either nodes and edges (CSV) or graphml, not both")
    if graphml is None and (nodes is None or edges is None):
        raise r.fail("streets", "needs nodes and edges (OSMnx node/edge CSV files) or graphml")
    crs = r.get(t, "streets", "crs", str, default="EPSG:4326")
    if r.validate:
        from pyproj import CRS
        from pyproj.exceptions import CRSError

        try:
            CRS.from_user_input(crs)
        except CRSError:
            raise r.fail("streets.crs", f"{crs!r} is not a coordinate system pyproj knows (e.g. EPSG:4326, EPSG:32618)") from None
    return StreetsSpec(nodes=nodes, edges=edges, graphml=graphml, crs=crs)


def _zones(r: _Reader, doc: dict) -> ZonesSpec:
    t = r.table(doc, "zones", ("file", "id_field", "name_field", "groups", "group", "borough", "ids", "missing"), required=True)
    assert t is not None
    file = r.file(t, "zones", "file", required=True)
    assert file is not None
    if file.suffix.lower() == ".shp" and not file.with_suffix(".prj").is_file():
        raise r.fail("zones.file", f"shapefile {file} has no .prj file beside it; cannot tell its coordinate system")
    chosen = [k for k in ("group", "borough", "ids") if k in t]
    if len(chosen) != 1:
        raise r.fail("zones", "choose the zones with exactly one of group, borough or ids (a list, or \"all\")")
    key = chosen[0]
    groups = r.file(t, "zones", "groups", required=key in ("group", "borough"))
    if key == "ids":
        ids = t["ids"]
        if ids == "all":
            select: tuple = ("all",)
        elif isinstance(ids, list) and ids and all(isinstance(i, int) and not isinstance(i, bool) for i in ids):
            select = ("ids", tuple(sorted(set(ids))))
        else:
            raise r.fail("zones.ids", f"expected a non-empty list of integer zone ids or \"all\", got {ids!r}")
    else:
        select = (key, r.get(t, "zones", key, str))
    missing = r.get(t, "zones", "missing", str, default="error")
    if missing not in ZONE_MISSING:
        raise r.fail("zones.missing", f"{missing!r} is not one of {', '.join(ZONE_MISSING)}")
    return ZonesSpec(file=file, id_field=r.get(t, "zones", "id_field", str, default="LocationID"),
                     name_field=r.get(t, "zones", "name_field", str, default="zone"), groups=groups, select=select, missing=missing)


def _weather(r: _Reader, doc: dict) -> WeatherSpec | None:
    t = r.table(doc, "weather", ("file", "station", "columns"))
    if t is None:
        return None
    file = r.file(t, "weather", "file", required=True)
    assert file is not None
    station = r.get(t, "weather", "station", str)
    columns = r.get(t, "weather", "columns", dict)
    if station is not None and columns is not None:
        raise r.fail("weather", "give station (an airport table) or columns (a generic table), not both")
    if columns is not None:
        r.known(columns, "weather.columns", WEATHER_COLUMNS)
        for k in WEATHER_COLUMNS:
            r.get(columns, "weather.columns", k, str, required=True)
    return WeatherSpec(file=file, station=station, columns=columns)


def _pois(r: _Reader, doc: dict) -> PoiSpec | None:
    t = r.table(doc, "pois", ("file", "borough", "types"))
    if t is None:
        return None
    file = r.file(t, "pois", "file", required=True)
    assert file is not None
    types = r.get(t, "pois", "types", dict)
    if types is not None:
        allowed = (*LOCALE_TYPES, "other")
        for k, v in types.items():
            if v not in allowed:
                raise r.fail(f"pois.types.{k}", f"{v!r} is not a locale type; use one of {', '.join(allowed)}")
    return PoiSpec(file=file, borough=r.get(t, "pois", "borough", int), types=types)


def _occupancy(r: _Reader, doc: dict) -> Path | None:
    t = r.table(doc, "occupancy", ("file",))
    return None if t is None else r.file(t, "occupancy", "file", required=True)


def _trips(r: _Reader, doc: dict) -> tuple[TripsSpec, ...]:
    """``[trips]``, or ``[[trips]]`` entries in order of preference (the world uses the first whose files exist)."""
    value = doc.get("trips")
    if value is None:
        return ()
    if isinstance(value, dict):
        return (_trip_entry(r, value, "trips"),)
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        return tuple(_trip_entry(r, v, f"trips[{k}]") for k, v in enumerate(value))
    raise r.fail("trips", f"expected a table ([trips]) or tables ([[trips]]), got {value!r}")


def _trip_entry(r: _Reader, t: dict, key: str) -> TripsSpec:
    r.known(t, key, ("kind", "files", "share", "optional"))
    kind = r.get(t, key, "kind", str, required=True)
    if kind not in TRIP_KINDS:
        raise r.fail(f"{key}.kind", f"{kind!r} is not one of {', '.join(TRIP_KINDS)}")
    raw = r.get(t, key, "files", (str, list), required=True)
    patterns = [raw] if isinstance(raw, str) else raw
    if not patterns or not all(isinstance(p, str) for p in patterns):
        raise r.fail(f"{key}.files", f"expected a path, a glob pattern or a list of them, got {raw!r}")
    optional = r.get(t, key, "optional", bool, default=False)
    files: list[Path] = []
    for pattern in patterns:
        resolved = r.resolve(f"{key}.files", pattern)
        found = sorted(Path(p) for p in glob.glob(str(resolved)))
        if not found and not optional:
            raise r.fail(f"{key}.files", f"no file matches {resolved}")
        files.extend(found)
    share = r.get(t, key, "share", (int, float))
    if share is not None and not 0.0 < float(share) <= 1.0:
        raise r.fail(f"{key}.share", f"{share!r} is not a share in (0, 1]")
    return TripsSpec(kind=kind, files=tuple(files), share=None if share is None else float(share), optional=optional)


def _events(r: _Reader, doc: dict) -> EventsSpec | None:
    t = r.table(doc, "events", ("file", "kind", "borough", "reviews"))
    if t is None:
        return None
    file = r.file(t, "events", "file", required=True)
    assert file is not None
    kind = r.get(t, "events", "kind", str, default="listing")
    if kind not in EVENT_KINDS:
        raise r.fail("events.kind", f"{kind!r} is not one of {', '.join(EVENT_KINDS)} (permitted: the NYC permitted-events CSV)")
    reviews = r.file(t, "events", "reviews")
    if reviews is not None and kind != "listing":
        raise r.fail("events.reviews", "reviews go with an event listing (kind = \"listing\")")
    return EventsSpec(file=file, kind=kind, borough=r.get(t, "events", "borough", str, default="Manhattan"), reviews=reviews)
