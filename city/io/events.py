"""Venues and events: what the demand world generates and what users' event files hold.

Event files (:func:`read_events`)
---------------------------------
CSV, one event per record, with a header::

    event_id,title,description,category,start,end,lat,lon[,venue,attendance]

``category`` is one of :data:`CATEGORIES`; ``start``/``end`` are ISO 8601
(``2022-03-01 19:30`` or ``2022-03-01T23:30:00Z``); ``lat``/``lon`` are WGS84
degrees; ``venue`` is free text and ``attendance`` a number (may be empty).

JSON: a list of event objects, or an object whose ``results`` is that list
(a PredictHQ Events API page). Each object has ``id`` (or ``event_id``),
``title``, ``description`` (optional), ``category``, ``start``, ``end``, a
position as ``location: [lon, lat]`` (PredictHQ order), ``geo.geometry``
(a GeoJSON point) or ``lat``/``lon`` fields, and optionally ``venue`` (or a
PredictHQ ``entities`` item of type ``venue``), ``attendance`` (or
``phq_attendance``), ``timezone`` and ``reviews`` (a list of strings).

Times with a UTC offset are converted to local wall-clock time in the event's
``timezone`` (default America/New_York); times without one are local.

Reviews (:func:`read_reviews`): CSV ``event_id,review``, one review per
record; at most :data:`MAX_REVIEWS` (the paper's Q = 100) are kept per event.

Error rows are the 1-based line on which the record starts, in CSV and JSON.
"""

from __future__ import annotations

import datetime as dt
import json
import math
import re
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING
from zoneinfo import ZoneInfo

import numpy as np

from city.errors import DataError

if TYPE_CHECKING:
    from city.graph import City

#: The event categories of the paper (PredictHQ names).
CATEGORIES: tuple[str, ...] = (
    "conferences",
    "expos",
    "concerts",
    "festivals",
    "performing-arts",
    "community",
    "sports",
)


@dataclass(frozen=True)
class Venue:
    venue_id: str
    name: str
    node: int
    sector: int
    capacity: int
    kind: str


@dataclass(frozen=True)
class Event:
    """One event at one venue; times are local, naive datetimes.

    ``attendance`` is known for synthetic events (ground truth that drives the
    surge) and ``None`` for real listings.
    """

    event_id: str
    title: str
    description: str
    category: str
    start: dt.datetime
    end: dt.datetime
    sector: int
    node: int
    venue_id: str = ""
    reviews: tuple[str, ...] = field(default_factory=tuple)
    attendance: float | None = None

    def active(self, hour_start: dt.datetime) -> bool:
        """Whether the event overlaps the hour beginning at ``hour_start``."""
        return self.start < hour_start + dt.timedelta(hours=1) and self.end > hour_start


#: Q: most reviews kept per event.
MAX_REVIEWS = 100
#: Events farther than this from every street node are outside the city and dropped.
MAX_EVENT_DISTANCE_M = 300.0
#: Default time zone for times written with a UTC offset.
DEFAULT_TZ = "America/New_York"
EVENT_COLUMNS: tuple[str, ...] = ("event_id", "title", "description", "category", "start", "end", "lat", "lon")


def read_reviews(path: Path | str) -> dict[str, list[str]]:
    """Reviews by event id from a CSV ``event_id,review``; empty reviews are skipped, at most Q kept."""
    from city.io.tables import read_csv

    table = read_csv(Path(path), ["event_id", "review"])
    out: dict[str, list[str]] = {}
    for event_id, review in zip(table.col("event_id"), table.col("review")):
        kept = out.setdefault(event_id, [])
        if review and len(kept) < MAX_REVIEWS:
            kept.append(review)
    return out


def read_events(
    path: Path | str, city: City, reviews: Path | str | None = None, tz: str = DEFAULT_TZ
) -> list[Event]:
    """Read an event listing (CSV or JSON, see the module docstring) and place it on ``city``.

    Each event goes to the street node nearest its position and that node's
    sector; events farther than :data:`MAX_EVENT_DISTANCE_M` from every node
    are dropped, with a warning giving the count. ``reviews`` is an optional
    reviews CSV, appended to any reviews the JSON carries (Q at most).

    Raises
    ------
    DataError
        A missing field, bad time or position, naming file and row.  Events of a
        category outside :data:`CATEGORIES` (PredictHQ has more) are skipped with
        one warning naming the categories and the first row.
    """
    from city.io.tables import nearest_nodes

    path = Path(path)
    records = _json_records(path) if _is_json(path) else _csv_records(path)
    extra = read_reviews(reviews) if reviews is not None else {}
    parsed = [_parse_event(rec, line, path, tz) for line, rec in records]
    unknown = [(line, p["category"]) for (line, _), p in zip(records, parsed) if p["category"] not in CATEGORIES]
    if unknown:
        names = ", ".join(sorted({c for _, c in unknown}))
        warnings.warn(
            f"{path}: skipped {len(unknown)} of {len(parsed)} events whose category is not one of {', '.join(CATEGORIES)} "
            f"({names}; first at row {unknown[0][0]})",
            stacklevel=2,
        )
        parsed = [p for p in parsed if p["category"] in CATEGORIES]
    if not parsed:
        return []
    lon = np.array([p["lon"] for p in parsed])
    lat = np.array([p["lat"] for p in parsed])
    node, inside = nearest_nodes(city, lon, lat, MAX_EVENT_DISTANCE_M)
    events = []
    for p, n, ok in zip(parsed, node, inside):
        if not ok:
            continue
        revs = (list(p["reviews"]) + extra.get(p["event_id"], []))[:MAX_REVIEWS]
        events.append(
            Event(
                event_id=p["event_id"],
                title=p["title"],
                description=p["description"],
                category=p["category"],
                start=p["start"],
                end=p["end"],
                sector=int(city.node_sector[n]),
                node=int(n),
                venue_id=p["venue"],
                reviews=tuple(revs),
                attendance=p["attendance"],
            )
        )
    if len(events) < len(parsed):
        dropped = len(parsed) - len(events)
        warnings.warn(f"{path}: dropped {dropped} of {len(parsed)} events outside the city's streets", stacklevel=2)
    return events


def _is_json(path: Path) -> bool:
    if path.suffix.lower() == ".json":
        return True
    try:
        with open(path, encoding="utf-8-sig") as fh:
            head = fh.read(256).lstrip()
    except OSError as exc:
        raise DataError(f"cannot open file ({exc.strerror or exc})", path=path) from None
    return head[:1] in ("[", "{")


def _csv_records(path: Path) -> list[tuple[int, dict]]:
    from city.io.tables import read_csv

    table = read_csv(path, list(EVENT_COLUMNS))
    names = list(table.columns)
    return [(int(line), {k: table.col(k)[i] for k in names}) for i, line in enumerate(table.lines)]


def _json_records(path: Path) -> list[tuple[int, dict]]:
    """Event objects of a JSON file with the line each starts on."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise DataError(f"cannot open file ({exc.strerror or exc})", path=path) from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise DataError(f"not valid JSON ({exc.msg})", path=path, row=exc.lineno) from None
    if isinstance(doc, dict) and isinstance(doc.get("results"), list):
        match = re.search(r'"results"\s*:\s*\[', text)
        start = match.end() - 1 if match else None
        items = doc["results"]
    elif isinstance(doc, list):
        start = len(text) - len(text.lstrip())
        items = doc
    else:
        raise DataError("expected a list of events or an object with a 'results' list", path=path, row=1)
    lines = _element_lines(text, start, len(items)) if start is not None else [1] * len(items)
    for line, item in zip(lines, items):
        if not isinstance(item, dict):
            raise DataError("an event must be a JSON object", path=path, row=line)
    return list(zip(lines, items))


def _element_lines(text: str, start: int, count: int) -> list[int]:
    """Line numbers of the elements of the JSON array opening at ``text[start]``."""
    decoder = json.JSONDecoder()
    pos, lines = start + 1, []
    for _ in range(count):
        while text[pos] in " \t\r\n,":
            pos += 1
        lines.append(text.count("\n", 0, pos) + 1)
        _, pos = decoder.raw_decode(text, pos)
    return lines


def _parse_event(rec: dict, line: int, path: Path, tz: str) -> dict:
    """Validate one event record (CSV or JSON) into plain values."""

    def fail(message: str) -> DataError:
        return DataError(message, path=path, row=line)

    def text(*keys: str, required: bool = True) -> str:
        for key in keys:
            value = rec.get(key)
            if value not in (None, ""):
                return str(value).strip()
        if required:
            raise fail(f"field '{keys[0]}' is missing or empty")
        return ""

    event_id = text("event_id", "id")
    category = text("category")  # an unknown category is skipped by the caller, with a warning
    zone = text("timezone", required=False) or tz
    start, end = (_local_time(text(k), zone, fail, k) for k in ("start", "end"))
    if end < start:
        raise fail(f"field 'end': {end} is before start {start}")
    lon, lat = _position(rec, fail)
    attendance = rec.get("attendance", rec.get("phq_attendance"))
    if attendance in (None, ""):
        attendance = None
    else:
        try:
            attendance = float(attendance)
        except (TypeError, ValueError):
            raise fail(f"field 'attendance': {attendance!r} is not a number") from None
    reviews = rec.get("reviews") or []
    if not isinstance(reviews, list) or not all(isinstance(r, str) for r in reviews):
        raise fail("field 'reviews' must be a list of strings")
    venue = text("venue", required=False)
    if not venue:
        entities = [e for e in rec.get("entities") or [] if isinstance(e, dict) and e.get("type") == "venue"]
        venue = str(entities[0].get("name", "")) if entities else ""
    return {
        "event_id": event_id,
        "title": text("title"),
        "description": text("description", required=False),
        "category": category,
        "start": start,
        "end": end,
        "lon": lon,
        "lat": lat,
        "venue": venue,
        "attendance": attendance,
        "reviews": [r for r in reviews if r.strip()],
    }


def _local_time(value: str, zone: str, fail: Callable[[str], DataError], key: str) -> dt.datetime:
    """ISO 8601 text as a naive local datetime; offsets are converted to ``zone``."""
    try:
        when = dt.datetime.fromisoformat(value)
    except ValueError:
        raise fail(f"field '{key}': {value!r} is not an ISO 8601 date/time") from None
    if when.tzinfo is not None:
        try:
            when = when.astimezone(ZoneInfo(zone)).replace(tzinfo=None)
        except (KeyError, ValueError):
            raise fail(f"field 'timezone': unknown time zone {zone!r}") from None
    return when


def _position(rec: dict, fail: Callable[[str], DataError]) -> tuple[float, float]:
    """(lon, lat) from ``location`` [lon, lat], a GeoJSON ``geo`` point, or ``lat``/``lon``."""
    if rec.get("lat") not in (None, "") or rec.get("lon") not in (None, ""):
        pair = (rec.get("lon"), rec.get("lat"))
    elif rec.get("location") is not None:
        pair = rec["location"]
    elif isinstance(rec.get("geo"), dict):
        pair = (rec["geo"].get("geometry") or {}).get("coordinates")
    else:
        raise fail("no position: give 'lat' and 'lon', or 'location' [lon, lat]")
    try:
        lon, lat = (float(v) for v in pair)
    except (TypeError, ValueError):
        raise fail(f"position {pair!r} is not a (lon, lat) pair of numbers") from None
    if not (math.isfinite(lon) and math.isfinite(lat) and -180 <= lon <= 180 and -90 <= lat <= 90):
        raise fail(f"position lon={lon}, lat={lat} is not a valid WGS84 coordinate")
    return lon, lat


# ----------------------------------------------------- NYC permitted events
#: NYC Open Data "NYC Permitted Event Information" event types and the paper category they stand for;
#: other types (film shoots, productions …) are read as ``community``.
PERMIT_CATEGORIES: dict[str, str] = {
    "Sport - Adult": "sports",
    "Sport - Youth": "sports",
    "Athletic - Charitable": "sports",
    "Parade": "festivals",
    "Street Event": "festivals",
    "Theater Load in and Load Outs": "performing-arts",
}
#: Approximate centres (lon, lat; about 100 m) of frequently permitted Manhattan places whose names
#: are not taxi-zone names. Places outside a city's streets are simply not matched.
LANDMARKS: dict[str, tuple[float, float]] = {
    "madison square park": (-73.9880, 40.7420),
    "washington square park": (-73.9973, 40.7308),
    "bryant park": (-73.9832, 40.7536),
    "tompkins square park": (-73.9817, 40.7265),
    "de witt clinton park": (-73.9935, 40.7668),
    "chelsea park": (-74.0002, 40.7497),
    "james j walker park": (-74.0058, 40.7307),
    "sara d roosevelt park": (-73.9928, 40.7195),
    "east river park": (-73.9750, 40.7180),
    "columbus park": (-73.9999, 40.7155),
    "city hall park": (-74.0068, 40.7126),
    "foley square": (-74.0032, 40.7142),
    "zuccotti park": (-74.0112, 40.7094),
    "stuyvesant square": (-73.9840, 40.7338),
    "herald square": (-73.9878, 40.7499),
    "rockefeller center": (-73.9787, 40.7587),
    "bowling green": (-74.0137, 40.7048),
    "corlears hook park": (-73.9800, 40.7115),
    "abingdon square": (-74.0052, 40.7373),
    "dag hammarskjold plaza": (-73.9682, 40.7530),
    "st vartan park": (-73.9737, 40.7450),
}
PERMIT_COLUMNS: tuple[str, ...] = (
    "Event ID", "Event Name", "Start Date/Time", "End Date/Time", "Event Type", "Event Borough", "Event Location",
)
PERMIT_TIME_FORMAT = "%m/%d/%Y %I:%M:%S %p"


def read_permitted_events(path: Path | str, city: City, borough: str = "Manhattan") -> list[Event]:
    """Read NYC Open Data "NYC Permitted Event Information" rows of ``borough`` as events.

    The file has names, times, a type and a location *text* (park, facility or
    street), but no coordinates, descriptions, reviews or attendance. An event
    is placed by matching its location text, case-insensitively and with
    "Square"/"Sq" and punctuation normalised, against the city's sector names
    (each ``/``-separated part, e.g. "Union Sq", "Times Sq", "Seaport") and a
    short list of landmark parks (:data:`LANDMARKS`); the earliest match in the
    text wins, the longest on ties. A zone match goes to the sector's most
    central node, a landmark to its nearest node. Unmatched events are dropped,
    with a warning giving the count. Descriptions and reviews are empty;
    categories come from :data:`PERMIT_CATEGORIES`.
    """
    from city.io.tables import nearest_nodes, parse_times, read_csv

    path = Path(path)
    table = read_csv(path, list(PERMIT_COLUMNS))
    table = table.subset(np.array([b.lower() == borough.lower() for b in table.col("Event Borough")], dtype=bool))
    starts = parse_times(table, "Start Date/Time", PERMIT_TIME_FORMAT).astype(dt.datetime)
    ends = parse_times(table, "End Date/Time", PERMIT_TIME_FORMAT).astype(dt.datetime)

    places: list[tuple[re.Pattern, int, int]] = []  # (pattern, sector, node)
    for s, name in enumerate(city.sector_names):
        nodes = np.flatnonzero(city.node_sector == s)
        centre = nodes[np.argmin(((city.xy[nodes] - city.xy[nodes].mean(axis=0)) ** 2).sum(axis=1))]
        for part in name.split("/"):
            if len(_normalise(part)) >= 3:
                places.append((re.compile(rf"\b{re.escape(_normalise(part))}\b"), s, int(centre)))
    coords = np.array(list(LANDMARKS.values()))
    node, inside = nearest_nodes(city, coords[:, 0], coords[:, 1])
    for key, n, ok in zip(LANDMARKS, node, inside):
        if ok:
            places.append((re.compile(rf"\b{re.escape(_normalise(key))}\b"), int(city.node_sector[n]), int(n)))

    events = []
    for i, location in enumerate(table.col("Event Location")):
        text = _normalise(location)
        hits = [(m.start(), -len(pat.pattern), s, n) for pat, s, n in places if (m := pat.search(text))]
        if not hits:
            continue
        _, _, sector, n = min(hits)
        if ends[i] < starts[i]:
            raise table.error(i, f"column 'End Date/Time': {ends[i]} is before the start {starts[i]}")
        events.append(
            Event(
                event_id=table.col("Event ID")[i],
                title=table.col("Event Name")[i],
                description="",
                category=PERMIT_CATEGORIES.get(table.col("Event Type")[i], "community"),
                start=starts[i],
                end=ends[i],
                sector=sector,
                node=n,
                venue_id=location.split(",")[0].strip(),
            )
        )
    if len(events) < len(table):
        dropped = len(table) - len(events)
        warnings.warn(f"{path}: {dropped} of {len(table)} {borough} events have no location in the city and were dropped", stacklevel=2)
    return events


def _normalise(text: str) -> str:
    """Lower case, ``square`` as ``sq``, punctuation as spaces: makes place names comparable."""
    text = re.sub(r"[^a-z0-9]+", " ", text.lower())
    return re.sub(r"\bsquare\b", "sq", text).strip()
