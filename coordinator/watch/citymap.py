"""What the map draws once: the street graph in page coordinates, sector membership, venues and their events by hour."""

from __future__ import annotations

import datetime as dt
from typing import Any

import numpy as np

from city.graph import City


def page_xy(city: City) -> np.ndarray:
    """Node coordinates scaled into the unit square, north up, the aspect kept (lon/lat maps shrunk east-west by cos lat)."""
    xy = np.asarray(city.xy, dtype=np.float64).copy()
    if city.crs != "m":
        xy[:, 0] *= np.cos(np.radians(np.mean(xy[:, 1])))
    xy -= xy.min(axis=0)
    span = float(xy.max()) or 1.0
    return xy / span


def street_pairs(city: City) -> np.ndarray:
    """Each street once, as ``(u, v)`` with ``u < v`` (a two-way street is one line on the map)."""
    u = np.repeat(np.arange(city.n_nodes), np.diff(city.indptr))
    v = np.asarray(city.indices)
    pairs = np.unique(np.sort(np.column_stack([u, v]), axis=1), axis=0)
    return pairs.astype(np.int64)


def events_by_hour(world: Any, date: dt.date, hour: int, hours: int) -> list[list[dict]]:
    """For each hour of the episode, the events active in it: title, venue node, sector, start and end (local time)."""
    start = dt.datetime.combine(date, dt.time(hour))
    out = []
    for h in range(hours):
        when = start + dt.timedelta(hours=h)
        out.append([{"title": ev.title, "node": int(ev.node), "sector": int(ev.sector), "start": ev.start.strftime("%H:%M"),
                     "end": ev.end.strftime("%H:%M"), "attendance": ev.attendance}
                    for ev in world.events_active(when)])
    return out


def city_map(city: City, world: Any, date: dt.date, hour: int, minutes: int) -> dict:
    """The page's static layer, as JSON-ready lists."""
    xy = page_xy(city)
    return {
        "name": city.name,
        "xy": np.round(xy, 5).ravel().tolist(),
        "streets": street_pairs(city).ravel().tolist(),
        "node_sector": np.asarray(city.node_sector).tolist(),
        "sectors": list(city.sector_names),
        "date": date.isoformat(),
        "hour": hour,
        "events": events_by_hour(world, date, hour, -(-minutes // 60)) if world is not None else [],
    }
