"""Points of interest and the locale counts n_λ(j) near each intersection."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from city.errors import DataError
from city.io.occupancy import LOCALE_TYPES


@dataclass(frozen=True)
class Pois:
    """Points of interest in the city's coordinate system; ``kind`` is a locale type or ``other``."""

    x: np.ndarray
    y: np.ndarray
    kind: np.ndarray
    name: np.ndarray


#: Radius of the locale counts n_λ(j), metres.
POI_RADIUS_M = 100.0


def metric_xy(xy: np.ndarray, crs: str, *, origin: np.ndarray | None = None) -> np.ndarray:
    """Coordinates in metres: ``xy`` itself for ``crs="m"``; lon/lat projected by pyproj.

    Lon/lat go to an azimuthal equidistant projection centred on ``origin``
    (default: the centre of ``xy``'s bounding box), so that distances from a
    city's centre are exact and, across a city, within a fraction of a per cent.
    """
    xy = np.asarray(xy, dtype=np.float64)
    if crs == "m":
        return xy
    if crs != "lonlat":
        raise ValueError(f"unknown coordinate system {crs!r}; expected 'm' or 'lonlat'")
    from pyproj import Transformer

    lon0, lat0 = origin if origin is not None else (xy.min(axis=0) + xy.max(axis=0)) / 2
    to_m = Transformer.from_crs("EPSG:4326", f"+proj=aeqd +lat_0={lat0} +lon_0={lon0} +datum=WGS84 +units=m", always_xy=True)
    return np.column_stack(to_m.transform(xy[:, 0], xy[:, 1]))


def locale_counts(xy: np.ndarray, crs: str, pois: Pois, radius_m: float = POI_RADIUS_M) -> np.ndarray:
    """n_λ(j): number of points of each locale type within ``radius_m`` metres of each intersection.

    ``xy`` and the points are in the map's coordinates ``crs`` (``m`` or
    ``lonlat``); both are measured in metres (:func:`metric_xy`).
    """
    xy = np.asarray(xy, dtype=np.float64)
    pts = np.column_stack([pois.x, pois.y]).astype(np.float64)
    origin = (xy.min(axis=0) + xy.max(axis=0)) / 2 if len(xy) else None
    return _counts_within(metric_xy(xy, crs, origin=origin), pois.kind, metric_xy(pts, crs, origin=origin), radius_m)


def _counts_within(xy: np.ndarray, kind: np.ndarray, pts: np.ndarray, radius: float) -> np.ndarray:
    from scipy.spatial import cKDTree

    tree = cKDTree(xy)
    counts = np.zeros((len(xy), len(LOCALE_TYPES)), dtype=np.float64)
    for k, loc in enumerate(LOCALE_TYPES):
        sel = pts[kind == loc]
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


def read_poi_csv(path: Path | str, borough: int | None = 1, types: dict[str, str] | None = None) -> Pois:
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
    the city's coordinates) with ``kind`` a locale type or ``other``, or any
    of the keys of ``types``, which maps the file's kinds to those.

    Raises
    ------
    DataError
        Bad WKT, coordinates or kind, naming the file and row.
    """
    from city.io.tables import read_csv

    path = Path(path)
    table = read_csv(path, [])
    if table.has("the_geom"):
        if types is not None:
            raise DataError("a type mapping applies to lon,lat,kind files; this NYC Planning export is mapped by FACILITY_T", path=path)
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
    if types is not None:
        bad = [i for i, k in enumerate(kind) if k not in types]
        if bad:
            raise table.error(bad[0], f"column 'kind': {kind[bad[0]]!r} is not in the type mapping ({', '.join(sorted(types))})")
        kind = np.array([types[k] for k in kind], dtype=object)
    bad = [i for i, k in enumerate(kind) if k not in allowed]
    if bad:
        raise table.error(bad[0], f"column 'kind': {kind[bad[0]]!r} is not one of {', '.join(sorted(allowed))}")
    names = np.array(table.col("name") if table.has("name") else [""] * len(table), dtype=object)
    return Pois(x=table.floats(xcol), y=table.floats(ycol), kind=kind, name=names)
