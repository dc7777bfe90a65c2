"""Scenario files: an invented city built entirely from files this test writes, and one-line errors for bad entries."""

from __future__ import annotations

import datetime as dt
import json
import re
from pathlib import Path

import numpy as np
import pytest

from city.demand import RecordedWorld
from city.errors import ConfigError
from city.io.occupancy import DAY_TYPES, LOCALE_TYPES
from city.scenario import load_scenario, scenario_spec
from coordinator.cli import main
from tests.city.test_loaders import write_fhvhv

UTM18N = "EPSG:32618"
GRID = 6  # 6 x 6 intersections, 150 m apart, in UTM zone 18N metres
E0, N0, STEP = 585_000.0, 4_511_000.0, 150.0


def _to_lonlat(e: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    from pyproj import Transformer

    return Transformer.from_crs(UTM18N, "EPSG:4326", always_xy=True).transform(e, n)


SCENARIO = """\
name = "invented"
timezone = "America/New_York"

[holidays]
country = "US"
subdiv = "NY"

[streets]
nodes = "streets/nodes.csv"
edges = "streets/edges.csv"
crs = "EPSG:32618"

[zones]
file = "zones.geojson"
id_field = "zone_id"
name_field = "label"
ids = "all"

[weather]
file = "weather.csv"
columns = { time = "when", temp_f = "temperature", precip_in = "rain", wind_mph = "wind" }

[pois]
file = "pois.csv"
types = { inn = "hotel", shop = "retail", diner = "restaurant", clinic = "hospital", park = "other" }

[occupancy]
file = "occupancy.csv"

[trips]
kind = "fhvhv"
files = "trips/*.parquet"
share = 0.5

[events]
file = "events.csv"
kind = "listing"
reviews = "reviews.csv"
"""


def write_invented_city(root: Path) -> Path:
    """Every input of a four-zone city, and the scenario file naming them; returns the file."""
    (root / "streets").mkdir(parents=True)
    (root / "trips").mkdir()
    ids = np.arange(GRID * GRID)
    e, n = E0 + STEP * (ids % GRID), N0 + STEP * (ids // GRID)
    (root / "streets" / "nodes.csv").write_text("osmid,x,y\n" + "".join(f"{100 + i},{x},{y}\n" for i, x, y in zip(ids, e, n)))
    edges = []
    for i in ids:
        for j in (i + 1 if i % GRID < GRID - 1 else None, i + GRID if i + GRID < GRID * GRID else None):
            if j is not None:
                edges += [f"{100 + i},{100 + j},{STEP}\n", f"{100 + j},{100 + i},{STEP}\n"]
    (root / "streets" / "edges.csv").write_text("u,v,length\n" + "".join(edges))

    half = E0 + STEP * (GRID - 1) / 2, N0 + STEP * (GRID - 1) / 2
    lo, hi = (E0 - STEP / 2, N0 - STEP / 2), (E0 + STEP * GRID, N0 + STEP * GRID)
    features = []
    for k, (x0, x1, y0, y1) in enumerate([(lo[0], half[0], lo[1], half[1]), (half[0], hi[0], lo[1], half[1]),
                                          (lo[0], half[0], half[1], hi[1]), (half[0], hi[0], half[1], hi[1])], start=1):
        lon, lat = _to_lonlat(np.array([x0, x1, x1, x0, x0]), np.array([y0, y0, y1, y1, y0]))
        features.append({"type": "Feature", "properties": {"zone_id": k, "label": f"Quarter {k}"},
                         "geometry": {"type": "Polygon", "coordinates": [list(map(list, zip(lon, lat)))]}})
    (root / "zones.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": features}))

    hours = np.arange(365 * 24)
    stamps = (np.datetime64("2022-01-01T00") + hours.astype("timedelta64[h]")).astype(str)
    (root / "weather.csv").write_text("when,temperature,rain,wind\n" + "".join(
        f"{t.replace('T', ' ')}:00,{50 + 10 * np.sin(h / 24):.1f},{0.1 if h % 97 == 0 else 0},{5 + h % 7}\n" for t, h in zip(stamps, hours)))

    plon, plat = _to_lonlat(E0 + STEP * np.array([0.2, 2.1, 4.9, 1.0, 3.0]), N0 + STEP * np.array([0.1, 3.9, 4.8, 1.2, 2.2]))
    (root / "pois.csv").write_text("lon,lat,kind,name\n" + "".join(
        f"{a},{b},{k},{k} {i}\n" for i, (a, b, k) in enumerate(zip(plon, plat, ["inn", "shop", "diner", "clinic", "park"]))))

    rows = [f"{loc},{day}," + ",".join(f"{(0.2 + 0.6 * (8 <= h <= 22)):.2f}" for h in range(24)) + "\n"
            for loc in LOCALE_TYPES for day in DAY_TYPES]
    (root / "occupancy.csv").write_text("schedule,day_type," + ",".join(f"h{h:02d}" for h in range(24)) + "\n" + "".join(rows))

    rng = np.random.default_rng(3)
    t0 = dt.datetime(2022, 11, 17, 18)
    trips = [(t0 + dt.timedelta(seconds=int(s)), t0 + dt.timedelta(seconds=int(s) + 200), int(rng.integers(1, 5)), int(rng.integers(1, 5)))
             for s in np.sort(rng.integers(0, 2 * 3600, 160))]
    write_fhvhv(root / "trips" / "fhvhv_tripdata_2022-11.parquet", trips)

    elon, elat = _to_lonlat(np.array([E0 + STEP * 4]), np.array([N0 + STEP * 4]))
    (root / "events.csv").write_text("event_id,title,description,category,start,end,lat,lon,venue,attendance\n"
                                     f"e1,Quarter fair,Stalls and music,festivals,2022-11-17 17:00,2022-11-17 21:00,{elat[0]},{elon[0]},Square,900\n")
    (root / "reviews.csv").write_text("event_id,review\ne1,Crowded but fun\ne1,Lovely music\n")
    path = root / "invented.toml"
    path.write_text(SCENARIO)
    return path


@pytest.fixture(scope="module")
def invented(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_invented_city(tmp_path_factory.mktemp("invented"))


def test_invented_city_is_built_from_its_scenario_file(invented: Path) -> None:
    scen = load_scenario(str(invented))
    city, world = scen.city, scen.world
    assert city.name == "invented" and city.crs == "lonlat"
    assert (city.n_nodes, city.n_sectors) == (GRID * GRID, 4)
    assert list(city.sector_names) == [f"Quarter {k}" for k in range(1, 5)]
    assert np.bincount(city.node_sector).tolist() == [9, 9, 9, 9]
    assert isinstance(world, RecordedWorld)
    assert 40 < world.hourly_counts().sum() < 120  # share 0.5 of 160 trips
    assert world.weather.source == "weather.csv"
    assert [ev.title for ev in world.events] == ["Quarter fair"] and len(world.events[0].reviews) == 2
    assert sorted(world.pois.kind.tolist()) == ["hospital", "hotel", "other", "restaurant", "retail"]
    assert scen.spec is not None and scen.spec.holidays == {"country": "US", "subdiv": "NY"}
    assert scen.schedules is not None and scen.schedules["hotel"]["sunday"][12] == 0.8


def test_the_scenario_calendar_and_schedules_drive_the_world_and_the_predictor(invented: Path) -> None:
    from city.calendar import holidays_for
    from city.io.occupancy import occupancy, sector_distribution
    from predictor.features import temporal_features

    scen = load_scenario(str(invented))
    world, city = scen.world, scen.city
    state_only = set(holidays_for(2022, "US", "NY")) - set(holidays_for(2022, "US"))
    assert state_only and state_only <= world.holidays
    day = min(state_only)
    assert temporal_features(dt.datetime.combine(day, dt.time(9)), world.holidays)[33] == 1.0
    assert temporal_features(dt.datetime.combine(day, dt.time(9)))[33] == 0.0
    pickup = np.asarray(city.pickup, bool)
    own = sector_distribution(occupancy(world.locale_counts, 12, "sunday", scen.schedules), city.node_sector, city.n_sectors, pickup)
    builtin = sector_distribution(occupancy(world.locale_counts, 12, "sunday"), city.node_sector, city.n_sectors, pickup)
    sunday_noon = dt.datetime(2022, 6, 5, 12)
    np.testing.assert_allclose(world.pickup_dist(sunday_noon), own)
    assert not np.allclose(own, builtin)


def test_surge_evaluate_runs_on_the_invented_city(invented: Path, capsys: pytest.CaptureFixture, tmp_path: Path) -> None:
    out = tmp_path / "results.json"
    assert main(["evaluate", "--scenario", str(invented), "--hours", "19", "--seeds", "2", "--taxis", "4", "--minutes", "20",
                 "--policies", "greedy", "ia", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"{invented}: 36 intersections" in printed and "4 sectors" in printed
    doc = json.loads(out.read_text())
    assert doc["scenario"] == str(invented) and len(doc["episodes"]) == 4


def _edit(invented: Path, old: str, new: str) -> Path:
    text = invented.read_text()
    assert old in text, old
    path = invented.parent / f"bad-{abs(hash((old, new)))}.toml"
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(("old", "new", "message"), [
    ('timezone = "America/New_York"', 'timezone = "Mars/Olympus"', "timezone: 'Mars/Olympus' is not an IANA timezone"),
    ('timezone = "America/New_York"\n', "", "timezone: missing"),
    ('name = "invented"', 'name = "invented"\ncolour = "red"', "colour: unknown key; expected one of name, data, timezone"),
    ('crs = "EPSG:32618"', 'crs = "EPSG:99999999"', "streets.crs: 'EPSG:99999999' is not a coordinate system pyproj knows"),
    ('edges = "streets/edges.csv"\n', "", "streets: needs nodes and edges"),
    ('nodes = "streets/nodes.csv"', 'nodes = "streets/missing.csv"', "streets.nodes: file .*streets/missing.csv does not exist"),
    ('ids = "all"', "ids = [1, 2]\ngroup = \"x\"", "zones: choose the zones with exactly one of group, borough or ids"),
    ('ids = "all"', 'ids = "some"', "zones.ids: expected a non-empty list of integer zone ids or \"all\", got 'some'"),
    ('ids = "all"', 'group = "north"', "zones.groups: missing"),
    ('share = 0.5', 'share = 2', "trips.share: 2 is not a share in \\(0, 1\\]"),
    ('kind = "fhvhv"', 'kind = "taxi"', "trips.kind: 'taxi' is not one of fhvhv, zone-od"),
    ('files = "trips/*.parquet"', 'files = "trips/*.csv"', "trips.files: no file matches"),
    ('clinic = "hospital"', 'clinic = "surgery"', "pois.types.clinic: 'surgery' is not a locale type"),
    ('subdiv = "NY"', 'subdiv = "ZZ"', "holidays: US has no subdivision 'ZZ'"),
    ('precip_in = "rain", ', '', "weather.columns.precip_in: missing"),
    ('[occupancy]\nfile = "occupancy.csv"', '[occupancy]\nfile = 3', "occupancy.file: expected str, got 3"),
    ('kind = "listing"', 'kind = "permitted"', "events.reviews: reviews go with an event listing"),
    ('nodes = "streets/nodes.csv"', 'nodes = "${data}/nodes.csv"', "streets.nodes: '\\$\\{data\\}/nodes.csv' is in the data directory; give it with --data DIR"),
])
def test_each_bad_entry_is_one_line_naming_file_and_key(invented: Path, old: str, new: str, message: str) -> None:
    path = _edit(invented, old, new)
    with pytest.raises(ConfigError) as err:
        scenario_spec(str(path))
    text = str(err.value)
    assert "\n" not in text and text.startswith(f"{path}: ")
    assert re.search(message, text), text


def test_zone_without_its_own_polygon_is_explained(invented: Path) -> None:
    """As TLC zone 103's polygon covers 104 and 105: zone 5 shares zone 4's name and has no polygon of its own."""
    (invented.parent / "groups.csv").write_text("".join(f"{k},Quarter {min(k, 4)},Invented,all\n" for k in range(1, 6)))
    path = _edit(invented, 'ids = "all"', 'groups = "groups.csv"\ngroup = "all"')
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(path))}: zones: zone\(s\) 5 have no polygon of their own in zones.geojson; "
                                          r"zone 4's polygon covers 5 \(same name 'Quarter 4'\); leave them out \(zones.missing = \"skip\""):
        load_scenario(str(path))
    skip = _edit(invented, 'ids = "all"', 'groups = "groups.csv"\ngroup = "all"\nmissing = "skip"')
    with pytest.warns(UserWarning, match=r"left out zone\(s\) 5"):
        assert load_scenario(str(skip)).city.n_sectors == 4


def test_cli_reports_a_bad_scenario_file_in_one_line(invented: Path, capsys: pytest.CaptureFixture) -> None:
    path = _edit(invented, 'share = 0.5', 'share = "half"')
    assert main(["evaluate", "--scenario", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"surge: error: {path}: trips.share: expected int or float, got 'half'"


def test_every_command_with_a_scenario_takes_a_scenario_file(invented: Path, capsys: pytest.CaptureFixture) -> None:
    from coordinator.cli import build_parser

    parser = build_parser()
    for command in (["evaluate"], ["city"], ["demand"], ["fleet"], ["coordinator"], ["bench", "sim"], ["bench", "plan"],
                    ["predictor", "train", "--out", "m"], ["predictor", "serve"]):
        assert parser.parse_args([*command, "--scenario", str(invented)]).scenario == str(invented), command
    assert main(["city", "--scenario", str(invented)]) == 0
    assert "invented: 36 intersections, 120 streets, 4 sectors" in capsys.readouterr().out


def test_trips_entries_in_order_of_preference_and_share_override(invented: Path) -> None:
    path = _edit(invented, '[trips]\nkind = "fhvhv"\nfiles = "trips/*.parquet"\nshare = 0.5\n',
                 '[[trips]]\nkind = "fhvhv"\nfiles = "downloads/*.parquet"\noptional = true\n\n'
                 '[[trips]]\nkind = "fhvhv"\nfiles = "trips/*.parquet"\n')
    spec = scenario_spec(str(path))
    assert spec is not None and [len(t.files) for t in spec.trips] == [0, 1] and spec.trips[1].share is None
    assert load_scenario(str(path)).world.hourly_counts().sum() == 160  # every trip: no share given
    assert load_scenario(str(path), share=0.25).world.hourly_counts().sum() < 80


def test_the_synthetic_scenario_says_it_reads_no_data(tmp_path: Path) -> None:
    from city.scenario import check_scenario

    with pytest.warns(UserWarning, match=r"synthetic scenario reads no data: --data .* is not used"):
        assert check_scenario("synthetic", tmp_path) is None
    with pytest.raises(ConfigError, match="data directory .*missing does not exist"):
        check_scenario("synthetic", tmp_path / "missing")
