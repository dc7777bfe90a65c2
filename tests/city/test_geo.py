"""Library-backed geography: metric POI radius on lon/lat maps, shapefile projections through pyproj."""

from __future__ import annotations

import numpy as np
import pytest

from city.errors import DataError
from city.io.occupancy import LOCALE_TYPES
from city.io.poi import Pois, locale_counts, metric_xy
from city.io.street_map import lonlat_transform_from_prj

LAT = 40.75
M_PER_DEG_LAT = 111_000.0


def test_poi_radius_is_metres_on_a_lonlat_map() -> None:
    node = np.array([[-73.98, LAT], [-73.90, LAT]])
    north_90 = LAT + 90 / M_PER_DEG_LAT
    north_120 = LAT + 120 / M_PER_DEG_LAT  # 0.00108 degrees: inside the old 0.0012-degree radius
    pois = Pois(x=np.array([-73.98, -73.98]), y=np.array([north_90, north_120]),
                kind=np.array(["hotel", "hotel"], dtype=object), name=np.array(["a", "b"], dtype=object))
    counts = locale_counts(node, "lonlat", pois, radius_m=100.0)
    assert counts[0, LOCALE_TYPES.index("hotel")] == 1 and counts[1].sum() == 0
    assert locale_counts(node, "lonlat", pois, radius_m=130.0)[0, LOCALE_TYPES.index("hotel")] == 2


def test_metric_xy_keeps_distances() -> None:
    xy = np.array([[-74.0, 40.70], [-73.93, 40.80]])
    m = metric_xy(xy, "lonlat")
    from pyproj import Geod

    _, _, dist = Geod(ellps="WGS84").inv(xy[0, 0], xy[0, 1], xy[1, 0], xy[1, 1])
    assert abs(np.hypot(*(m[1] - m[0])) - dist) < 0.001 * dist
    assert metric_xy(xy, "m") is not None and np.array_equal(metric_xy(m, "m"), m)


def test_prj_in_lonlat_needs_no_transform_and_a_bad_prj_is_one_line(tmp_path) -> None:
    from pyproj import CRS

    assert lonlat_transform_from_prj(CRS.from_epsg(4326).to_wkt("WKT1_ESRI")) is None
    to_lonlat = lonlat_transform_from_prj(CRS.from_epsg(2263).to_wkt("WKT1_ESRI"))
    lon, lat = to_lonlat(np.array([[988_000.0, 211_000.0]]))[0]  # midtown Manhattan, NY Long Island ftUS
    assert -74.0 < lon < -73.97 and 40.73 < lat < 40.76
    with pytest.raises(DataError, match=r"zones\.prj: unreadable coordinate system"):
        lonlat_transform_from_prj("PROJCS[nonsense", tmp_path / "zones.prj")


def test_poi_type_mapping_names_the_row_of_an_unmapped_kind(tmp_path) -> None:
    from city.io.poi import read_poi_csv

    path = tmp_path / "pois.csv"
    path.write_text("lon,lat,kind\n-73.98,40.75,inn\n-73.97,40.76,zoo\n")
    with pytest.raises(DataError, match=r"pois\.csv, row 3: column 'kind': 'zoo' is not in the type mapping \(inn\)"):
        read_poi_csv(path, types={"inn": "hotel"})
    assert read_poi_csv(path, types={"inn": "hotel", "zoo": "other"}).kind.tolist() == ["hotel", "other"]
