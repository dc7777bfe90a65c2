"""Real hourly trip totals and per-zone hourly counts: their loaders, scenario wiring, and the real level of every hour."""

from __future__ import annotations

import datetime as dt
import json
import os
from pathlib import Path

import numpy as np
import pytest

from city.demand import synthetic_world
from city.demand.real_level import BASE_FLOOR, day_kinds, real_base, sector_split, usual_by_kind_hour
from city.errors import ConfigError, DataError
from city.io.hourly_totals import read_hourly_totals
from city.io.zone_hourly import read_zone_hourly
from city.io.weather import HourlyWeather, hours_in_year
from tests.city.test_zone_profile import ZONES, write_profile, zone_city

SHARED = Path(os.environ.get("SURGE_SHARED_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
TRIPS = SHARED / "nyc" / "trips"
HOURLY = TRIPS / "manhattan_hourly_trips_2019_2024.parquet"
ZONE_HOURLY = TRIPS / "yellow_zone_hourly_2022_01.parquet"
H = hours_in_year(2022)


def year_counts(seed: int = 0) -> np.ndarray:
    """A made-up year of hourly totals with a daily cycle (the tests' own numbers, not real ones)."""
    hour = np.arange(H) % 24
    return np.round(1000 + 800 * np.sin((hour - 6) / 24 * 2 * np.pi) + np.random.default_rng(seed).integers(0, 300, H))


def write_hourly_csv(path: Path, counts: np.ndarray, header: str = "date,hour,trip_count,yellow,uber") -> Path:
    """The shared file's layout as CSV: ``date, hour, trip_count`` and two company columns."""
    start = dt.date(2022, 1, 1)
    lines = [header]
    for h, c in enumerate(counts):
        day = start + dt.timedelta(days=h // 24)
        lines.append(f"{day.isoformat()},{h % 24},{int(c)},{int(c) // 3},{int(c) - int(c) // 3}")
    path.write_text("\n".join(lines) + "\n")
    return path


def write_hourly_parquet(path: Path, counts: np.ndarray) -> Path:
    """The shared file's parquet layout: ``date`` as dates, ``hour`` int32, ``trip_count`` int64, ``via`` with nulls."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    days = [dt.date(2022, 1, 1) + dt.timedelta(days=h // 24) for h in range(len(counts))]
    table = pa.table({"date": pa.array(days, pa.date32()), "hour": pa.array(np.arange(len(counts)) % 24, pa.int32()),
                      "trip_count": pa.array(counts.astype(np.int64)), "via": pa.array([None] * len(counts), pa.float64())})
    pq.write_table(table, path)
    return path


def write_zone_parquet(path: Path, rows: list[tuple[str, int, int]]) -> Path:
    """The layout of ``yellow_zone_hourly_2022_01.parquet``: ``pickup_hour`` timestamp, ``rides``, ``pickup_location_id``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({"pickup_hour": pa.array([np.datetime64(t, "us") for t, _, _ in rows], pa.timestamp("us")),
                      "rides": pa.array([c for _, _, c in rows], pa.int64()),
                      "pickup_location_id": pa.array([z for _, z, _ in rows], pa.int64())})
    pq.write_table(table, path)
    return path


ZONE_COLUMNS = {"time": "pickup_hour", "zone": "pickup_location_id", "count": "rides"}


# ----------------------------------------------------------------- loaders
def test_hourly_totals_from_csv_and_parquet(tmp_path: Path) -> None:
    counts = year_counts()
    from_csv = read_hourly_totals(write_hourly_csv(tmp_path / "h.csv", counts), columns={"count": "trip_count"})
    np.testing.assert_array_equal(from_csv.year(2022), counts)
    assert sorted(from_csv.companies) == ["uber", "yellow"] and from_csv.source == "h.csv"
    np.testing.assert_array_equal(from_csv.companies["yellow"] + from_csv.companies["uber"], counts)
    from_parquet = read_hourly_totals(write_hourly_parquet(tmp_path / "h.parquet", counts), columns={"count": "trip_count"})
    np.testing.assert_array_equal(from_parquet.year(2022), counts)
    np.testing.assert_array_equal(from_parquet.companies["via"], 0.0)  # empty cells read as 0
    assert from_parquet.covers(2022) and not from_parquet.covers(2023)
    with pytest.raises(DataError, match=r"h\.parquet: no count for 2023-01-01 hour 0 \(8760 of the 8760 hours of 2023 missing\)"):
        from_parquet.year(2023)


def test_hourly_totals_rows_in_any_order_and_a_missing_hour(tmp_path: Path) -> None:
    path = tmp_path / "h.csv"
    path.write_text("date,hour,count\n2022-01-01,1,5\n2022-01-01,0,7\n")
    t = read_hourly_totals(path)
    np.testing.assert_array_equal(t.count, [7, 5])
    with pytest.raises(DataError, match=r"no count for 2022-01-01 hour 2"):
        t.year(2022)


@pytest.mark.parametrize(("text", "match"), [
    ("date,hour,count\n2022-01-01,0,5\n2022-13-01,1,5\n", r"h\.csv, row 3: field 'date': '2022-13-01' is not a date"),
    ("date,hour,count\n2022-01-01,24,5\n", r"h\.csv, row 2: field 'hour': '24' is not an integer in 0\.\.23"),
    ("date,hour,count\n2022-01-01,1.5,5\n", r"row 2: field 'hour': '1\.5' is not an integer"),
    ("date,hour,count\n2022-01-01,3,-2\n", r"row 2: field 'count': '-2' is not a number ≥ 0"),
    ("date,hour,count\n2022-01-01,3,\n", r"row 2: field 'count': '' is not a number"),
    ("date,hour,count\n2022-01-01,3,4\n2022-01-02,3,4\n2022-01-01,3,6\n", r"row 4: field 'hour': 2022-01-01 hour 3 is also on row 2"),
    ("date,hr,count\n2022-01-01,3,4\n", r"h\.csv, row 1: missing column\(s\) 'hour'"),
])
def test_hourly_totals_errors_name_file_row_and_field(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "h.csv"
    path.write_text(text)
    with pytest.raises(DataError, match=match) as err:
        read_hourly_totals(path)
    assert "\n" not in str(err.value)


def test_hourly_totals_parquet_errors_name_the_row(tmp_path: Path) -> None:
    counts = year_counts()[:48].copy()
    counts[30] = -1
    with pytest.raises(DataError, match=r"h\.parquet, row 31: field 'trip_count': .*-1.* is not a number ≥ 0"):
        read_hourly_totals(write_hourly_parquet(tmp_path / "h.parquet", counts), columns={"count": "trip_count"})
    with pytest.raises(DataError, match=r"h\.parquet, row 1: missing column\(s\) 'count'"):
        read_hourly_totals(tmp_path / "h.parquet")
    with pytest.raises(DataError, match=r"missing column\(s\) 'lyft'"):
        read_hourly_totals(tmp_path / "h.parquet", columns={"count": "trip_count"}, companies=("lyft",))
    (tmp_path / "bad.parquet").write_text("not parquet")
    with pytest.raises(DataError, match=r"bad\.parquet: not a readable parquet file"):
        read_hourly_totals(tmp_path / "bad.parquet")


def test_zone_hourly_from_parquet_and_csv_by_day_type(tmp_path: Path) -> None:
    rows = [("2022-01-03T19:00", 10, 6), ("2022-01-03T19:00", 20, 2), ("2022-01-08T19:00", 10, 1),  # Monday, Saturday
            ("2022-01-09T19:00", 20, 4), ("2022-01-17T19:00", 20, 8), ("2022-01-03T08:00", 999, 50)]  # Sunday, MLK day
    z = read_zone_hourly(write_zone_parquet(tmp_path / "z.parquet", rows), columns=ZONE_COLUMNS)
    assert len(z) == 6 and z.count.sum() == 71
    from city.demand.dates import holiday_dates

    mean, days = z.by_day_type(np.array(ZONES), holiday_dates(2022))
    np.testing.assert_array_equal(days, [1, 1, 2])
    np.testing.assert_allclose(mean[:, 19, :2], [[6, 2], [1, 0], [0, 6]])  # zone 999 is not in the city
    csv = tmp_path / "z.csv"
    csv.write_text("time,zone,count\n" + "".join(f"{t.replace('T', ' ')},{zone},{c}\n" for t, zone, c in rows))
    np.testing.assert_array_equal(read_zone_hourly(csv).count, z.count)


@pytest.mark.parametrize(("text", "match"), [
    ("time,zone,count\n2022-01-03 19:00,10,6\n2022-01-03 19:30,10,6\n", r"z\.csv, row 3: field 'time': .*19:30:00 is not the start of an hour"),
    ("time,zone,count\nyesterday,10,6\n", r"row 2: field 'time': 'yesterday' is not a date/time"),
    ("time,zone,count\n2022-01-03 19:00,x,6\n", r"row 2: field 'zone': 'x' is not an integer ≥ 1"),
    ("time,zone,count\n2022-01-03 19:00,10,many\n", r"row 2: field 'count': 'many' is not a number"),
    ("time,zone,count\n2022-01-03 19:00,10,6\n2022-01-03 19:00,10,7\n", r"row 3: field 'zone': zone 10 at 2022-01-03T19:00 is also on row 2"),
    ("time,zone\n2022-01-03 19:00,10\n", r"z\.csv, row 1: missing column\(s\) 'count'"),
])
def test_zone_hourly_errors_name_file_row_and_field(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "z.csv"
    path.write_text(text)
    with pytest.raises(DataError, match=match) as err:
        read_zone_hourly(path)
    assert "\n" not in str(err.value)


# ----------------------------------------------------------------- the real level
def test_split_sums_to_one_in_every_mode() -> None:
    rng = np.random.default_rng(1)
    profile, by_type, fallback = rng.random((5, 24, 4)), rng.random((3, 24, 4)), rng.random((24, 4))
    by_type[:, :, 3] = 0.0  # a zone with no counts
    for p, z in ((profile, by_type), (profile, None), (None, by_type), (None, None)):
        split = sector_split(p, z, fallback)
        assert split.shape == (7, 24, 4)
        np.testing.assert_allclose(split.sum(axis=2), 1.0)
    split = sector_split(profile, by_type, fallback)
    np.testing.assert_allclose(split[1, 7], profile[1, 7] / profile[1, 7].sum())  # a business day keeps its weekday's shares
    ratio = (by_type[1, 20] + 1.0) / (by_type[0, 20] + 1.0)
    weekend = profile.mean(axis=0)[20] * ratio
    np.testing.assert_allclose(split[5, 20], weekend / weekend.sum())  # Saturday: weekday mean × weekend ratio


def test_no_events_the_expected_total_is_the_scaled_real_count() -> None:
    totals = year_counts()
    kinds = day_kinds(2022, frozenset())
    split = sector_split(None, None, np.full((24, 3), 1 / 3))
    base, floored = real_base(totals, 0.02, split, kinds, np.zeros(H), kinds)
    assert floored == 0
    np.testing.assert_allclose(base.sum(axis=1), totals * 0.02)


def test_events_count_only_above_their_usual_level() -> None:
    totals = year_counts()
    kinds = day_kinds(2022, frozenset())
    events = np.zeros(H)
    events[np.arange(19, H, 24)] = 2.0  # every evening at 19 h
    events[(dt.date(2022, 11, 17).timetuple().tm_yday - 1) * 24 + 19] = 30.0  # and a surge
    split = sector_split(None, None, np.full((24, 3), 1 / 3))
    base, _ = real_base(totals, 0.02, split, kinds, events, kinds)
    expected = base.sum(axis=1) + events
    usual = usual_by_kind_hour(events, kinds)
    np.testing.assert_allclose(expected, totals * 0.02 + events - usual)
    for k in range(7):  # over the year, each day kind and hour keeps its real total
        hours = np.flatnonzero(np.repeat(kinds == k, 24))
        np.testing.assert_allclose(expected[hours].reshape(-1, 24).sum(axis=0), (totals * 0.02)[hours].reshape(-1, 24).sum(axis=0))
    np.testing.assert_allclose(expected[np.arange(3, H, 24)], totals[np.arange(3, H, 24)] * 0.02)  # no events at 3 h


@pytest.fixture(scope="module")
def city():
    return zone_city()


@pytest.fixture(scope="module")
def profile(city, tmp_path_factory: pytest.TempPathFactory):
    from city.io.trips import read_zone_profile

    rows = [(d, s, a, b, 51 * (1 + (a == 10) + d)) for d in range(5) for s in range(0, 96, 2) for a in ZONES for b in ZONES]
    return read_zone_profile(write_profile(tmp_path_factory.mktemp("p") / "p.csv", rows), city)


def weather(rain: float) -> HourlyWeather:
    return HourlyWeather(2022, np.full(H, 60.0), np.full(H, rain), np.full(H, 5.0), f"rain {rain}")


def test_world_level_is_the_files_count_times_share(tmp_path: Path, city, profile) -> None:
    counts = year_counts()
    totals = read_hourly_totals(write_hourly_csv(tmp_path / "h.csv", counts), columns={"count": "trip_count"})
    w = synthetic_world(city, seed=1, weather=weather(0.0), zone_profile=profile, hourly_totals=totals, share=0.05)
    np.testing.assert_allclose(w.real_level(), counts * 0.05)
    thursday = w.hour_index(dt.datetime(2022, 11, 17, 19))
    assert w.real_level()[thursday] == counts[thursday] * 0.05
    events = w.event_rate().sum(axis=1)
    level = counts * 0.05
    weekdays = day_kinds(2022, frozenset())  # the usual event level is per weekday: the calendar ignores holidays
    base = np.maximum(level - usual_by_kind_hour(events, weekdays), BASE_FLOOR * level)  # the tiny city's events are large
    np.testing.assert_allclose(w.expected_rate().sum(axis=1), base + events, rtol=1e-9)
    business = w.base_rate()[w.hour_index(dt.datetime(2022, 3, 8, 9))]  # a Tuesday: the profile's Tuesday 9 h shares
    np.testing.assert_allclose(business / business.sum(), profile.rate()[1, 9] / profile.rate()[1, 9].sum())
    rainy = synthetic_world(city, seed=1, weather=weather(0.3), zone_profile=profile, hourly_totals=totals, share=0.05)
    np.testing.assert_allclose(rainy.real_level(), w.real_level())  # the real total holds the weather: no factor on top
    assert w.demand_source.startswith("hourly-totals h.csv + zone-od p.csv") and "share 0.05" in w.demand_source
    old = synthetic_world(city, seed=1, weather=weather(0.0), zone_profile=profile, share=0.05)
    assert old.real_level() is None and old.demand_source == "zone-od p.csv, share 0.05"


def test_default_share_puts_the_reference_hour_at_ref_rate(tmp_path: Path, city, profile) -> None:
    from city.demand.profile import REF_RATE

    counts = year_counts()
    totals = read_hourly_totals(write_hourly_csv(tmp_path / "h.csv", counts), columns={"count": "trip_count"})
    w = synthetic_world(city, seed=1, weather=weather(0.0), zone_profile=profile, hourly_totals=totals)
    kinds = day_kinds(2022, w.holidays)
    first_half = np.array([(dt.date(2022, 1, 1) + dt.timedelta(days=d)).month <= 6 for d in range(365)])
    assert w.real_level().reshape(-1, 24)[(kinds < 5) & first_half, 19].mean() == pytest.approx(REF_RATE)


# ----------------------------------------------------------------- scenario files
def test_a_users_city_uses_hourly_totals_and_zone_counts(tmp_path: Path) -> None:
    from city.scenario import load_scenario
    from tests.city.test_scenario_files import write_invented_city

    path = write_invented_city(tmp_path)
    counts = year_counts()
    write_hourly_csv(tmp_path / "trips" / "hourly.csv", counts, header="day,hour,n,yellow,uber")
    rows = [(f"2022-01-{d:02d}T{h:02d}:00", z, d + h + 3 * z) for d in range(3, 17) for h in range(24) for z in (1, 2, 3, 4)]
    write_zone_parquet(tmp_path / "trips" / "zones.parquet", rows)
    text = path.read_text().replace('[trips]\nkind = "fhvhv"\nfiles = "trips/*.parquet"\nshare = 0.5\n',
                                    '[[trips]]\nkind = "hourly-totals"\nfiles = "trips/hourly.csv"\nshare = 0.04\n'
                                    'columns = { date = "day", count = "n" }\n\n'
                                    '[[trips]]\nkind = "zone-hourly"\nfiles = "trips/zones.parquet"\n'
                                    'columns = { time = "pickup_hour", zone = "pickup_location_id", count = "rides" }\n')
    path.write_text(text)
    world = load_scenario(str(path)).world
    np.testing.assert_allclose(world.real_level(), counts * 0.04)
    assert "split by zone counts zones.parquet" in world.base_source
    sat = world.base_rate()[world.hour_index(dt.datetime(2022, 1, 8, 10))]
    assert np.argmax(sat) == 3  # zone 4 has the most counts
    bad = path.read_text().replace('count = "n" }', 'total = "n" }')
    path.write_text(bad)
    with pytest.raises(ConfigError, match=r"trips\[0\]\.columns\.total: unknown key; expected one of date, hour, count"):
        load_scenario(str(path))
    path.write_text(text.replace('files = "trips/zones.parquet"\n', 'files = "trips/zones.parquet"\nshare = 0.1\n'))
    with pytest.raises(ConfigError, match=r"trips\[1\]\.share: zone-hourly counts only split demand"):
        load_scenario(str(path))


def test_a_resumed_run_refuses_another_demand_source(tmp_path: Path) -> None:
    from dataclasses import asdict

    from coordinator.experiments.evaluate import EvalConfig, load_finished
    from coordinator.experiments.results import RESULTS_SCHEMA, UNRECORDED_SOURCE, same_demand

    cfg = EvalConfig(seeds=1, hours=[19], policies=["greedy", "oracle"])
    doc = {"schema": RESULTS_SCHEMA, "reference_oracle": "oracle", "city": {}, "config": asdict(cfg), "episodes": [],
           "demand_source": "hourly-totals manhattan_hourly_trips_2019_2024.parquet, share 0.0158"}
    path = tmp_path / "r.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(DataError, match=r"r\.json: was written with demand source 'hourly-totals manhattan_hourly_trips_2019_2024\.parquet, "
                                        r"share 0\.0158', this run has 'synthetic profile, share 0\.0170\d*'"):
        load_finished(cfg, path)
    del doc["demand_source"]
    path.write_text(json.dumps(doc))
    assert load_finished(cfg, path) == []  # written before the field, and this world has no hourly totals
    assert not same_demand(UNRECORDED_SOURCE, "hourly-totals h.csv, share 0.02")


# ----------------------------------------------------------------- the shared files
needs_hourly = pytest.mark.skipif(not HOURLY.exists() or not ZONE_HOURLY.exists(), reason="../shared/data trips files not available")


@needs_hourly
def test_the_shared_files_read_as_their_readme_says() -> None:
    totals = read_hourly_totals(HOURLY, columns={"count": "trip_count"})
    year = totals.year(2022)
    assert year.sum() == pytest.approx(94.8e6, rel=1e-3)
    day = (dt.date(2022, 11, 17).timetuple().tm_yday - 1) * 24
    np.testing.assert_array_equal(year[day + np.array([15, 17, 19, 21])], [13698, 17620, 21666, 18228])
    assert sorted(totals.companies) == ["juno", "lyft", "uber", "via", "yellow"]
    zones = read_zone_hourly(ZONE_HOURLY, columns=ZONE_COLUMNS)
    assert zones.count.sum() == 2_463_879 and len(np.unique(zones.zone)) == 257


@needs_hourly
def test_nyc_runs_at_the_real_level_of_every_hour() -> None:
    from city.scenario import load_scenario

    with pytest.warns(UserWarning):
        world = load_scenario("nyc", SHARED).world
    totals = read_hourly_totals(HOURLY, columns={"count": "trip_count"}).year(2022)
    np.testing.assert_allclose(world.real_level(), totals * world.share)
    assert world.demand_source.startswith("hourly-totals manhattan_hourly_trips_2019_2024.parquet + zone-od "
                                          "manhattan_zone_od_15min_2018.csv + zone-hourly yellow_zone_hourly_2022_01.parquet")
    np.testing.assert_allclose(world.expected_rate().sum(), totals.sum() * world.share, rtol=1e-3)


def test_level_check_of_a_world_at_the_real_level_and_of_one_off_by_a_factor() -> None:
    from types import SimpleNamespace

    from city.demand.level_check import level_table

    totals = year_counts()
    exact = SimpleNamespace(expected_rate=lambda: np.column_stack([totals * 0.01, totals * 0.01]), event_rate=lambda: np.zeros((H, 2)))
    table = level_table(exact, totals)
    assert table["scale"] == pytest.approx(0.02) and table["all_hours"]["r"] == pytest.approx(1.0) and table["all_hours"]["mape_pct"] == 0
    assert all(row["ratio_vs_usual_weekday"] == pytest.approx(1.0) for row in table["named"])
    doubled = totals.copy()
    doubled[np.arange(H) % 24 == 8] *= 2  # every 8 h twice too high: the MAPE of 8 h shows it, the named rows too
    off = SimpleNamespace(expected_rate=lambda: doubled[:, None] * 0.02, event_rate=lambda: np.zeros((H, 1)))
    table = level_table(off, totals)
    assert table["by_hour"][8]["mape_pct"] > table["by_hour"][9]["mape_pct"]
