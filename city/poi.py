"""Points of interest and the locale counts n_λ(j) near each intersection."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from city.occupancy import LOCALE_TYPES


@dataclass(frozen=True)
class Pois:
    """Points of interest in the city's coordinate system; ``kind`` is a locale type or ``other``."""

    x: np.ndarray
    y: np.ndarray
    kind: np.ndarray
    name: np.ndarray


def locale_counts_from_pois(xy: np.ndarray, pois: Pois, radius: float) -> np.ndarray:
    """n_λ(j): number of points of each locale type within ``radius`` of each intersection.

    ``radius`` is in the units of ``xy`` (metres, or degrees for lon/lat maps).
    """
    from scipy.spatial import cKDTree

    tree = cKDTree(np.asarray(xy, dtype=np.float64))
    counts = np.zeros((len(xy), len(LOCALE_TYPES)), dtype=np.float64)
    pts = np.column_stack([pois.x, pois.y]).astype(np.float64)
    for k, loc in enumerate(LOCALE_TYPES):
        sel = pts[pois.kind == loc]
        if len(sel) == 0:
            continue
        for neigh in tree.query_ball_point(sel, r=radius):
            counts[neigh, k] += 1.0
    return counts


#: NYC Planning ``FACILITY_T`` codes (Points of Interest data dictionary) used here.
FACILITY_COMMERCIAL, FACILITY_HEALTH = 7, 10
#: ``FACI_DOM`` sub-codes: commercial 4 = hotel/motel, 5 = restaurant; health 1 = hospital.
DOMAIN_HOTEL, DOMAIN_RESTAURANT, DOMAIN_HOSPITAL = 4, 5, 1
_HOTEL = re.compile(r"\b(HOTEL|HOTL|INN|SUITES|HOSTEL)\b")
_HOSPITAL = re.compile(r"\b(HOSPITAL|HOSP|MEDICAL CENTER)\b")
_POINT = re.compile(r"^\s*POINT\s*\(\s*(\S+)\s+(\S+)\s*\)\s*$", re.IGNORECASE)


def read_poi_csv(path: Path | str, borough: int | None = 1) -> Pois:
    """Read points of interest as lon/lat points with a locale type.

    Two schemas are accepted. The NYC Planning "Points of Interest" export
    (``the_geom`` as WKT ``POINT (lon lat)``, ``FACILITY_T``, ``FACI_DOM``,
    ``NAME``, ``BOROUGH``), kept to ``borough`` (1 = Manhattan; ``None`` keeps
    all) and mapped as:

    * commercial (``FACILITY_T`` 7): ``hotel`` when ``FACI_DOM`` is 4 or the
      name says HOTEL/HOTL/INN/SUITES/HOSTEL; ``restaurant`` when ``FACI_DOM``
      is 5; otherwise ``retail`` (malls, markets, businesses);
    * health (10): ``hospital`` when ``FACI_DOM`` is 1 or the name says
      HOSPITAL/HOSP/MEDICAL CENTER; clinics and the rest are ``other``;
    * every other facility type: ``other``.

    The file lists notable places only: it has no individual shops and only a
    few landmark restaurants (about 120 citywide), so restaurant and retail
    counts understate the real density; they still rank areas.

    The generic schema is ``lon,lat,kind[,name]`` (or ``x,y,kind[,name]`` in
    the city's coordinates) with ``kind`` a locale type or ``other``.

    Raises
    ------
    DataError
        Bad WKT, coordinates or kind, naming the file and row.
    """
    from city.csvio import read_csv

    path = Path(path)
    table = read_csv(path, [])
    if table.has("the_geom"):
        table.require(["the_geom", "FACILITY_T", "NAME"])
        if borough is not None:
            table.require(["BOROUGH"])
            boro = table.floats("BOROUGH", allow_empty=True)
            table = table.subset(boro == borough)
        xy = np.empty((len(table), 2))
        for i, wkt in enumerate(table.col("the_geom")):
            m = _POINT.match(wkt)
            try:
                xy[i] = float(m.group(1)), float(m.group(2))  # type: ignore[union-attr]
            except (AttributeError, ValueError):
                raise table.error(i, f"column 'the_geom': {wkt[:60]!r} is not a WKT POINT (lon lat)") from None
        names = np.array(table.col("NAME"), dtype=object)
        upper = [n.upper() for n in names]
        facility = table.ints("FACILITY_T")
        domain = table.ints("FACI_DOM") if table.has("FACI_DOM") else np.zeros(len(table), dtype=np.int64)
        commercial, health = facility == FACILITY_COMMERCIAL, facility == FACILITY_HEALTH
        hotel = commercial & ((domain == DOMAIN_HOTEL) | np.array([bool(_HOTEL.search(n)) for n in upper], dtype=bool))
        restaurant = commercial & ~hotel & (domain == DOMAIN_RESTAURANT)
        hospital = health & ((domain == DOMAIN_HOSPITAL) | np.array([bool(_HOSPITAL.search(n)) for n in upper], dtype=bool))
        kind = np.select([hotel, restaurant, commercial, hospital], ["hotel", "restaurant", "retail", "hospital"], "other")
        return Pois(x=xy[:, 0], y=xy[:, 1], kind=kind.astype(object), name=names)

    xcol, ycol = ("lon", "lat") if table.has("lon") else ("x", "y")
    table.require([xcol, ycol, "kind"])
    kind = np.array(table.col("kind"), dtype=object)
    allowed = set(LOCALE_TYPES) | {"other"}
    bad = [i for i, k in enumerate(kind) if k not in allowed]
    if bad:
        raise table.error(bad[0], f"column 'kind': {kind[bad[0]]!r} is not one of {', '.join(sorted(allowed))}")
    names = np.array(table.col("name") if table.has("name") else [""] * len(table), dtype=object)
    return Pois(x=table.floats(xcol), y=table.floats(ycol), kind=kind, name=names)
