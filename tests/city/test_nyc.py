"""The real-map loader: street CSV/GraphML parsing, zone clipping, and the real NYC map."""

from __future__ import annotations

import json
import shutil
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from city.errors import ConfigError, DataError
from city.io.street_map import load_nyc_city, read_street_csv, read_taxi_zones

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"
NODES = "osmid,x,y\n1,-73.995,40.705\n2,-73.985,40.705\n3,-73.995,40.708\n4,-73.985,40.708\n5,-73.970,40.705\n6,-73.996,40.709\n"
EDGES = "u,v,length\n9706\n1,2,80\n2,1,80\n1,3,30\n3,1,30\n2,4,30\n4,2,30\n3,4,80\n4,3,80\n2,5,120\n5,2,120\n1,6,40\n"


def _square(x0: float, y0: float, side: float = 0.01) -> list:
    return [[[x0, y0], [x0 + side, y0], [x0 + side, y0 + side], [x0, y0 + side], [x0, y0]]]


def write_dataset(root: Path, nodes: str = NODES, edges: str = EDGES) -> Path:
    """A tiny dataset laid out like shared/data: two adjacent zones in group ``test`` and one far zone."""
    street, zones = root / "nyc" / "street_network", root / "nyc" / "taxi_zones"
    street.mkdir(parents=True)
    zones.mkdir(parents=True)
    (street / "tiny_drive_nodes.csv").write_text(nodes)
    (street / "tiny_drive_edges.csv").write_text(edges)
    feats = [
        {"type": "Feature", "properties": {"LocationID": zid, "zone": name}, "geometry": {"type": "Polygon", "coordinates": _square(x, 40.70)}}
        for zid, name, x in [(2, "Zone Two", -73.99), (1, "Zone One", -74.00), (3, "Far", -73.90)]
    ]
    (zones / "taxi_zones_wgs84.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    (zones / "taxi_zone_groups.csv").write_text("1,Zone One,Manhattan,test\n2,Zone Two,Manhattan,test\n3,Far,Queens,other\n")
    return root


def test_tiny_map_clips_to_zones_and_scc(tmp_path):
    with pytest.warns(UserWarning, match=r"tiny_drive_edges\.csv, row 2: skipping stray row"):
        city = load_nyc_city(write_dataset(tmp_path), zone_group="test")
    assert city.crs == "lonlat"
    assert city.n_nodes == 4 and city.n_sectors == 2
    assert list(city.sector_ids) == [1, 2] and city.sector_names == ("Zone One", "Zone Two")
    assert list(city.osmid) == [1, 2, 3, 4]
    assert list(city.node_sector) == [0, 1, 0, 1]
    assert city.info["dropped"] == {"nodes_outside_zones": 1, "edges_outside_zones": 2, "nodes_outside_scc": 1, "edges_outside_scc": 1}
    assert "row 2" in city.info["warnings"][0]
    assert city.sector_adj[0, 1] and city.sector_adj[1, 0]


def test_explicit_zone_list(tmp_path):
    with pytest.warns(UserWarning):
        city = load_nyc_city(write_dataset(tmp_path) / "nyc", zones=[1])
    assert city.n_nodes == 2 and city.sector_names == ("Zone One",)


def test_bad_edge_row_names_file_and_line(tmp_path):
    write_dataset(tmp_path, edges="u,v,length\n1,2,80\n2,1,80\n1,3,abc\n")
    with pytest.raises(DataError, match=r"tiny_drive_edges\.csv, row 4: column 'length': 'abc' is not a number"):
        load_nyc_city(tmp_path, zone_group="test")


def test_edge_to_unknown_node(tmp_path):
    nodes, edges = tmp_path / "n.csv", tmp_path / "e.csv"
    nodes.write_text(NODES)
    edges.write_text("u,v,length\n1,2,80\n2,99,80\n")
    with pytest.raises(DataError, match=r"e\.csv, row 3: column 'v': node 99 is not in n\.csv"):
        read_street_csv(nodes, edges)


def test_non_numeric_node_id(tmp_path):
    nodes, edges = tmp_path / "n.csv", tmp_path / "e.csv"
    nodes.write_text("osmid,x,y\n1,-73.9,40.7\nx2,-73.9,40.7\n")
    edges.write_text("u,v,length\n")
    with pytest.raises(DataError, match=r"n\.csv, row 3: column 'osmid': 'x2' is not an integer"):
        read_street_csv(nodes, edges)


def test_missing_column(tmp_path):
    nodes, edges = tmp_path / "n.csv", tmp_path / "e.csv"
    nodes.write_text("osmid,lon,lat\n1,-73.9,40.7\n")
    edges.write_text("u,v,length\n")
    with pytest.raises(DataError, match=r"n\.csv, row 1: missing column\(s\) 'x', 'y'"):
        read_street_csv(nodes, edges)


def test_missing_directory_and_files(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_nyc_city(tmp_path / "nowhere")
    (tmp_path / "nyc" / "street_network").mkdir(parents=True)
    with pytest.raises(DataError, match="street_network"):
        load_nyc_city(tmp_path)


def test_unknown_zone_group(tmp_path):
    with pytest.warns(UserWarning), pytest.raises(ConfigError, match="unknown zone group 'nope'.*other, test"):
        load_nyc_city(write_dataset(tmp_path), zone_group="nope")


def test_graphml_street_network(tmp_path):
    import networkx as nx

    write_dataset(tmp_path)
    street = tmp_path / "nyc" / "street_network"
    graph = nx.MultiDiGraph()
    for line in NODES.splitlines()[1:]:
        osmid, x, y = line.split(",")
        graph.add_node(osmid, x=x, y=y)  # OSMnx writes attributes as strings
    for line in EDGES.splitlines()[2:]:
        u, v, length = line.split(",")
        graph.add_edge(u, v, length=length)
    for f in street.glob("*.csv"):
        f.unlink()
    nx.write_graphml(graph, street / "tiny.graphml")
    city = load_nyc_city(tmp_path, zone_group="test")
    assert city.n_nodes == 4 and city.info["source"]["streets"] == "tiny.graphml"
    assert sorted(city.osmid) == [1, 2, 3, 4]


# ------------------------------------------------------------- real data
needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data not available")


@pytest.fixture(scope="module")
def nyc():
    if not SHARED.is_dir():
        pytest.skip("../shared/data not available")
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        city = load_nyc_city(SHARED)
    return city, time.perf_counter() - start, [str(w.message) for w in caught]


def test_real_nyc_map(nyc):
    city, seconds, caught = nyc
    assert 2000 <= city.n_nodes <= 2300
    assert city.n_sectors == 38 and len(set(city.sector_ids)) == 38
    assert 230 in city.sector_ids and "Times Sq/Theatre District" in city.sector_names
    adj = csr_matrix((city.edge_length, city.indices, city.indptr), shape=(city.n_nodes, city.n_nodes))
    assert connected_components(adj, directed=True, connection="strong")[0] == 1
    assert np.bincount(city.node_sector, minlength=38).min() > 0
    assert (city.sector_adj.sum(axis=1) > 0).all()
    assert city.info["dropped"]["nodes_outside_zones"] == 4507 - 2177
    assert any("manhattan_drive_edges.csv, row 2" in w for w in caught)
    assert seconds < 15


@needs_shared
def test_shapefile_matches_geojson(tmp_path):
    src = SHARED / "nyc" / "taxi_zones"
    for ext in ("shp", "shx", "dbf", "prj"):
        shutil.copy(src / f"taxi_zones.{ext}", tmp_path)
    projected, names, source = read_taxi_zones(tmp_path)
    reference, ref_names, _ = read_taxi_zones(src)
    assert source == "taxi_zones.shp" and names == ref_names
    for zid in (4, 161, 230, 261):
        assert projected[zid].hausdorff_distance(reference[zid]) < 1e-5  # about a metre
