"""The real NYC map: OSM street network clipped to TLC taxi zones, and the shared file readers.

The street network is read from the node/edge CSV pair OSMnx users export
(``osmid,x,y`` and ``u,v,length``) or from an OSMnx GraphML file; the taxi
zones from the WGS84 GeoJSON or the official shapefile (EPSG:2263, taken to
lon/lat with pyproj from the ``.prj`` file).

The CSV helpers at the bottom are shared by every real-format reader in
:mod:`city`: they keep the 1-based line number of each record, so an error
names the line a user sees in an editor even when quoted fields span lines.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import shape

from city.errors import ConfigError, DataError
from city.graph import City, largest_scc
from city.io.tables import read_csv

#: Two zone polygons closer than this (degrees, about 5 m) count as sharing a border.
BORDER_TOLERANCE_DEG = 5e-5


def load_nyc_city(data_dir: Path, zone_group: str = "manhattan_below_60", zones: list[int] | None = None) -> City:
    """Load the NYC street graph clipped to a group of TLC taxi zones, from a folder laid out like ``shared/data``.

    Parameters
    ----------
    data_dir : Path
        A folder laid out like ``shared/data`` (holding ``nyc/``) or that ``nyc/`` folder itself.
    zone_group : str
        A group of ``taxi_zones/taxi_zone_groups.csv``; ignored when ``zones`` is given.
    zones : list of int, optional
        Explicit TLC LocationIDs to keep.

    Returns
    -------
    City
        As :func:`build_zone_map`.

    Raises
    ------
    ConfigError
        Missing data directory, unknown zone group or zone id.
    DataError
        Missing or malformed files (the message names file and line).
    """
    root = Path(data_dir)
    if not root.is_dir():
        raise ConfigError(f"NYC data directory not found: {root}")
    if (root / "nyc").is_dir():
        root = root / "nyc"
    street_dir, zone_dir = root / "street_network", root / "taxi_zones"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        streets = _read_streets(street_dir)
    notes = [str(w.message) for w in caught]
    for note in notes:
        warnings.warn(note, stacklevel=2)
    zone_file = _zone_file(zone_dir)
    polygons, zone_names = read_zone_file(zone_file)
    groups = zone_dir / "taxi_zone_groups.csv"
    if zones is not None:
        ids = sorted({int(z) for z in zones})
    else:
        ids = zone_ids_in_group(groups, "group", zone_group)
    check_zone_polygons(ids, polygons, zone_names, zone_file, known=zone_names_in_groups(groups) if groups.is_file() else {})
    return build_zone_map("nyc", streets, polygons, zone_names, ids, zone_src=zone_file.name, notes=notes,
                          info={"zone_group": None if zones is not None else zone_group})


def build_zone_map(
    name: str,
    streets: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, str],
    polygons: dict[int, shapely.Geometry],
    zone_names: dict[int, str],
    ids: list[int],
    *,
    zone_src: str,
    notes: list[str] | None = None,
    info: dict | None = None,
) -> City:
    """A street graph in lon/lat clipped to the zones ``ids``, one sector per zone.

    Parameters
    ----------
    streets : tuple
        ``(osmid, xy, u, v, length, source)`` as :func:`read_street_csv` and
        :func:`read_graphml` return, ``xy`` in lon/lat.
    polygons, zone_names : dict
        Zone polygons in lon/lat and names, by zone id (:func:`read_zone_file`).
    ids : list of int
        The zones to keep, each with a polygon (:func:`check_zone_polygons`).

    Returns
    -------
    City
        Sectors are the zones in ``ids`` order; ``xy`` is lon/lat
        (``crs="lonlat"``). ``info["dropped"]`` counts the nodes outside the
        zones, the edges losing an end, and the nodes and edges outside the
        largest strongly connected component; ``info["warnings"]`` holds the
        file problems that were skipped.
    """
    osmid, xy, u, v, length, street_src = streets
    names = [zone_names[i] for i in ids]
    polys = [polygons[i] for i in ids]

    node_zone = np.full(len(xy), -1, dtype=np.int64)
    for k, poly in enumerate(polys):
        hit = (node_zone < 0) & shapely.intersects_xy(poly, xy[:, 0], xy[:, 1])
        node_zone[hit] = k
    inside = node_zone >= 0
    keep_edge = inside[u] & inside[v]
    new_index = np.cumsum(inside) - 1
    n_in = int(inside.sum())
    if n_in == 0:
        raise ConfigError(f"no intersection of {street_src} lies inside the chosen zones of {zone_src}; "
                          "are the street coordinates lon/lat (or is the streets crs set)?")
    u1, v1, len1 = new_index[u[keep_edge]], new_index[v[keep_edge]], length[keep_edge]
    scc = largest_scc(n_in, u1, v1)
    keep_scc = scc[u1] & scc[v1]
    final_index = np.cumsum(scc) - 1

    border = np.zeros((len(ids), len(ids)), dtype=bool)
    for k, poly in enumerate(polys):
        border[k] = shapely.dwithin(poly, np.asarray(polys, dtype=object), BORDER_TOLERANCE_DEG)

    nodes_kept = np.flatnonzero(inside)[scc]
    # A zone none of whose intersections is in the component (an island, a park) has no street to serve.
    present = np.bincount(node_zone[nodes_kept], minlength=len(ids)) > 0
    empty = [ids[k] for k in np.flatnonzero(~present)]
    notes = list(notes or [])
    if empty:
        notes.append(f"zone(s) {', '.join(map(str, empty))} of {zone_src} hold no intersection of the street network "
                     "(after its largest strongly connected component) and are not sectors")
        warnings.warn(notes[-1], stacklevel=2)
        renumber = np.cumsum(present) - 1
        node_zone = np.where(node_zone >= 0, renumber[np.maximum(node_zone, 0)], -1)
        ids = [z for z, keep in zip(ids, present) if keep]
        names = [n for n, keep in zip(names, present) if keep]
        border = border[np.ix_(present, present)]
    dropped = {
        "nodes_outside_zones": int(len(xy) - n_in),
        "edges_outside_zones": int(len(u) - keep_edge.sum()),
        "nodes_outside_scc": int(n_in - scc.sum()),
        "edges_outside_scc": int(len(u1) - keep_scc.sum()),
    }
    info = {
        "source": {"streets": street_src, "zones": zone_src},
        **(info or {}),
        "nodes_read": int(len(xy)),
        "edges_read": int(len(u)),
        "dropped": dropped,
        "zones_without_intersections": empty,
        "warnings": notes,
    }
    return City.build(
        name,
        xy[nodes_kept],
        final_index[u1[keep_scc]],
        final_index[v1[keep_scc]],
        len1[keep_scc],
        node_zone[nodes_kept],
        names,
        crs="lonlat",
        sector_ids=np.asarray(ids, dtype=np.int64),
        osmid=osmid[nodes_kept],
        border_adj=border,
        info=info,
    )


# ------------------------------------------------------------------ streets
def _read_streets(street_dir: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    """Node/edge CSVs if present, else the single GraphML file of the folder."""
    if not street_dir.is_dir():
        raise DataError("street network folder not found", path=street_dir)
    nodes = sorted(street_dir.glob("*_nodes.csv"))
    edges = sorted(street_dir.glob("*_edges.csv"))
    if nodes and edges:
        return (*read_street_csv(nodes[0], edges[0]), str(nodes[0].name))
    graphml = sorted(street_dir.glob("*.graphml"))
    if graphml:
        return (*read_graphml(graphml[0]), str(graphml[0].name))
    raise DataError("no *_nodes.csv/*_edges.csv pair or *.graphml street network", path=street_dir)


def read_street_csv(nodes_path: Path, edges_path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Read an OSMnx-style node CSV (``osmid,x,y``) and edge CSV (``u,v,length``).

    A row holding only its first field (the stray ``9706`` line of the
    published Manhattan file) is skipped with a warning; any other bad row
    raises.

    Returns
    -------
    osmid, xy, u, v, length
        ``u`` and ``v`` are indices into ``osmid``/``xy``; ``length`` in metres.
    """
    nodes = read_csv(nodes_path, ["osmid", "x", "y"])
    osmid = nodes.ints("osmid")
    xy = np.column_stack([nodes.floats("x"), nodes.floats("y")])
    order = np.argsort(osmid, kind="stable")
    dup = np.flatnonzero(osmid[order][1:] == osmid[order][:-1])
    if len(dup):
        raise DataError(f"duplicate osmid {osmid[order][dup[0]]}", path=nodes_path, row=int(nodes.lines[order][dup[0] + 1]))

    edges = read_csv(edges_path, ["u", "v", "length"])
    stray = np.array([v == "" and w == "" for v, w in zip(edges.col("v"), edges.col("length"))], dtype=bool)
    for line in edges.lines[stray]:
        warnings.warn(f"{edges_path}, row {line}: skipping stray row with no 'v' and 'length'", stacklevel=2)
    edges = edges.subset(~stray)
    u_id, v_id, length = edges.ints("u"), edges.ints("v"), edges.floats("length")
    if len(length) and (np.isnan(length).any() or (length < 0).any()):
        bad = int(np.flatnonzero(np.isnan(length) | (length < 0))[0])
        raise edges.error(bad, f"column 'length': {edges.col('length')[bad]!r} is not a non-negative length")
    sorted_ids = osmid[order]
    idx = []
    for name, ids in (("u", u_id), ("v", v_id)):
        pos = np.clip(np.searchsorted(sorted_ids, ids), 0, max(len(sorted_ids) - 1, 0))
        missing = np.flatnonzero(sorted_ids[pos] != ids) if len(sorted_ids) else np.arange(len(ids))
        if len(missing):
            raise edges.error(int(missing[0]), f"column '{name}': node {ids[missing[0]]} is not in {nodes_path.name}")
        idx.append(order[pos])
    return osmid, xy, idx[0], idx[1], length


def read_graphml(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Read an OSMnx GraphML file (node attributes ``x``, ``y``; edge attribute ``length``).

    Returns the same arrays as :func:`read_street_csv`; node ids that are not
    integers are numbered in file order.
    """
    import networkx as nx

    try:
        graph = nx.read_graphml(path, force_multigraph=True)
    except (OSError, SyntaxError, nx.NetworkXError, ValueError) as exc:
        raise DataError(f"not a readable GraphML file ({exc})", path=path) from exc
    names = list(graph.nodes)
    index = {name: i for i, name in enumerate(names)}
    xy = np.empty((len(names), 2))
    for i, (name, attrs) in enumerate(graph.nodes(data=True)):
        try:
            xy[i] = float(attrs["x"]), float(attrs["y"])
        except (KeyError, TypeError, ValueError):
            raise DataError(f"node {name!r} lacks numeric 'x' and 'y' attributes", path=path) from None
    try:
        osmid = np.array([int(n) for n in names], dtype=np.int64)
    except ValueError:
        osmid = np.arange(len(names), dtype=np.int64)
    rows = []
    for a, b, attrs in graph.edges(data=True):
        try:
            rows.append((index[a], index[b], float(attrs["length"])))
        except (KeyError, TypeError, ValueError):
            raise DataError(f"edge {a!r} -> {b!r} lacks a numeric 'length' attribute", path=path) from None
    arr = np.array(rows, dtype=np.float64).reshape(-1, 3)
    return osmid, xy, arr[:, 0].astype(np.int64), arr[:, 1].astype(np.int64), arr[:, 2]


# -------------------------------------------------------------------- zones
def read_taxi_zones(zone_dir: Path) -> tuple[dict[int, shapely.Geometry], dict[int, str], str]:
    """TLC taxi-zone polygons in lon/lat, by LocationID, and their names, from the folder's zone file.

    Prefers ``*.geojson``; otherwise reads ``*.shp`` with its ``.prj``.
    """
    path = _zone_file(zone_dir)
    polygons, names = read_zone_file(path)
    return polygons, names, path.name


def _zone_file(zone_dir: Path) -> Path:
    if not zone_dir.is_dir():
        raise DataError("taxi zone folder not found", path=zone_dir)
    found = sorted(zone_dir.glob("*.geojson")) or sorted(zone_dir.glob("*.shp"))
    if not found:
        raise DataError("no taxi_zones *.geojson or *.shp file", path=zone_dir)
    return found[0]


def read_zone_file(path: Path, id_field: str = "LocationID", name_field: str = "zone") -> tuple[dict[int, shapely.Geometry], dict[int, str]]:
    """Zone polygons in lon/lat and names, by zone id, from a GeoJSON file (WGS84) or a shapefile with its ``.prj``.

    Field names match case-insensitively.  Features sharing an id (a zone in
    several polygons) are merged.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError("zone file not found", path=path)
    if path.suffix.lower() == ".shp":
        features, transform = _read_shapefile(path)
    else:
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise DataError(f"not a readable GeoJSON file ({exc})", path=path) from exc
        features = [(f.get("properties") or {}, f.get("geometry")) for f in doc.get("features", [])]
        transform = None
    id_key, name_key = id_field.lower(), name_field.lower()
    parts: dict[int, list[shapely.Geometry]] = {}
    names: dict[int, str] = {}
    for k, (props, geom) in enumerate(features, start=1):
        props = {key.lower(): val for key, val in props.items()}
        try:
            zone_id = int(props[id_key])
            poly = shape(geom)
        except (KeyError, TypeError, ValueError, AttributeError, shapely.errors.GEOSException) as exc:
            raise DataError(f"feature {k}: needs a {id_field!r} field and a polygon ({exc})", path=path) from None
        if transform is not None:
            poly = shapely.transform(poly, transform)
        parts.setdefault(zone_id, []).append(shapely.make_valid(poly))
        names.setdefault(zone_id, str(props.get(name_key, zone_id)))
    if not parts:
        raise DataError("no zone features", path=path)
    polygons = {zid: shapely.union_all(p) if len(p) > 1 else p[0] for zid, p in parts.items()}
    for poly in polygons.values():
        shapely.prepare(poly)
    return polygons, names


def _read_shapefile(path: Path) -> tuple[list[tuple[dict, dict]], Callable[[np.ndarray], np.ndarray] | None]:
    """Records and geometries of a shapefile, and the transform to lon/lat its ``.prj`` implies."""
    import shapefile

    prj = path.with_suffix(".prj")
    if not prj.is_file():
        raise DataError("shapefile has no .prj file; cannot tell its coordinate system", path=path)
    transform = lonlat_transform_from_prj(prj.read_text(encoding="utf-8", errors="replace"), prj)
    try:
        with shapefile.Reader(str(path)) as reader:
            fields = [f[0] for f in reader.fields[1:]]
            features = [(dict(zip(fields, sr.record)), sr.shape.__geo_interface__) for sr in reader.iterShapeRecords()]
    except (OSError, shapefile.ShapefileException) as exc:
        raise DataError(f"not a readable shapefile ({exc})", path=path) from exc
    return features, transform


def lonlat_transform_from_prj(wkt: str, path: Path | None = None) -> Callable[[np.ndarray], np.ndarray] | None:
    """A function mapping ``(n, 2)`` coordinates of the ``.prj`` WKT's system to lon/lat (WGS84), by pyproj.

    A file already in WGS84 lon/lat gives ``None`` (no transform).
    """
    from pyproj import CRS, Transformer
    from pyproj.exceptions import CRSError

    try:
        crs = CRS.from_wkt(wkt)
    except CRSError as exc:
        raise DataError(f"unreadable coordinate system ({exc})", path=path) from None
    if crs.equals(CRS.from_epsg(4326), ignore_axis_order=True):
        return None
    transformer = Transformer.from_crs(crs, "EPSG:4326", always_xy=True)

    def to_lonlat(coords: np.ndarray) -> np.ndarray:
        return np.column_stack(transformer.transform(coords[:, 0], coords[:, 1]))

    return to_lonlat


GROUP_COLUMNS = ["LocationID", "Zone", "Borough", "group"]


def zone_ids_in_group(path: Path, column: str, value: str) -> list[int]:
    """The zone ids whose ``column`` (``group`` or ``Borough``) is ``value`` in a TLC-style groups CSV.

    The file has no header: ``LocationID,Zone,Borough,group`` (``taxi_zone_groups.csv``).
    """
    table = read_csv(Path(path), GROUP_COLUMNS, header=False)
    values = np.array(table.col(column))
    chosen = sorted(set(table.ints("LocationID")[values == value].tolist()))
    if not chosen:
        raise ConfigError(f"unknown zone {column.lower()} {value!r} in {path} ({column.lower()}s: {', '.join(sorted(set(values)))})")
    return chosen


def zone_names_in_groups(path: Path) -> dict[int, str]:
    """Zone id → name from a TLC-style groups CSV (the names tell which zones share a polygon)."""
    table = read_csv(Path(path), GROUP_COLUMNS, header=False)
    return dict(zip(table.ints("LocationID").tolist(), table.col("Zone")))


def check_zone_polygons(ids: list[int], polygons: dict, names: dict[int, str], path: Path, *, known: dict[int, str] | None = None,
                        where: str | None = None) -> None:
    """Every zone of ``ids`` must have a polygon of its own; else one line says which, and why when it can tell.

    ``known`` (zone id → name, from a groups or lookup table) lets the message
    say when a missing zone's name is that of a zone whose polygon covers it
    (TLC zone 103's polygon covers 103–105).  ``where`` starts the message
    (default: the zone file).
    """
    if not ids:
        raise ConfigError("no zones chosen")
    missing = [z for z in ids if z not in polygons]
    if not missing:
        return
    by_name: dict[str, int] = {}
    for zid, name in names.items():
        by_name.setdefault(name, zid)
    covered: dict[int, list[int]] = {}
    for z in missing:
        if known and known.get(z) in by_name:
            covered.setdefault(by_name[known[z]], []).append(z)
    hint = "".join(f"; zone {owner}'s polygon covers {', '.join(map(str, zs))} (same name {names[owner]!r})" for owner, zs in covered.items())
    raise ConfigError(
        f"{where or path}: zone(s) {', '.join(map(str, missing))} have no polygon of their own in {path.name}{hint}; "
        "leave them out (zones.missing = \"skip\" in a scenario file, or list the ids)")
