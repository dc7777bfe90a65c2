"""The zone-to-zone trip profile loader, the real base demand built on it, and the base profile table."""

from __future__ import annotations

import datetime as dt
import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from city.demand import synthetic_world
from city.demand.profile import MONTH_FACTOR, PROFILE, REAL_TRIPS_19H, derive_tables
from city.errors import DataError
from city.graph import City
from city.io.trips import business_days, read_zone_profile
from city.io.weather import HourlyWeather, hours_in_year
from tests.conftest import grid_edges

SHARED = Path(os.environ.get("SURGE_SHARED_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
TRIPS = SHARED / "nyc" / "trips"
ZONES = (10, 20, 30, 40)


def zone_city(side: int = 6) -> City:
    """A two-way grid in four quadrant sectors with TLC-like zone ids 10, 20, 30, 40."""
    xy, u, v = grid_edges(side)
    half = side // 2 * 100.0
    sector = (xy[:, 0] >= half).astype(int) + 2 * (xy[:, 1] >= half).astype(int)
    names = ["Times Sq/Theatre District", "Penn Station/Madison Sq West", "Clinton West", "Battery Park"]
    return City.build("zones", xy, u, v, np.full(len(u), 100.0), sector, names, sector_ids=np.array(ZONES))


def write_profile(path: Path, rows: list[tuple], header: str = "dow,t_15min,puzone,dozone,n_trips") -> Path:
    path.write_text(header + "\n" + "".join(",".join(str(x) for x in r) + "\n" for r in rows))
    return path


@pytest.fixture(scope="module")
def city() -> City:
    return zone_city()


def test_counts_per_business_day_rate_and_beta(tmp_path: Path, city: City) -> None:
    days = business_days(2018)
    np.testing.assert_array_equal(days, [46, 51, 51, 51, 52])  # 2018 weekdays less US federal holidays
    rows = [(1, 76, 10, 20, 51 * 3), (1, 77, 10, 30, 51), (1, 76, 20, 20, 102), (0, 0, 40, 10, 46), (1, 76, 10, 999, 500), (2, 5, 30, 40, 51)]
    prof = read_zone_profile(write_profile(tmp_path / "p.csv", rows), city)
    assert prof.trips.shape == (5, 96, 4, 4) and prof.n_rows == 6 and prof.n_outside == 1 and prof.filled == ()
    assert prof.trips[1, 76, 0, 1] == pytest.approx(3.0) and prof.trips[0, 0, 3, 0] == pytest.approx(1.0)
    rate = prof.rate()
    assert rate[1, 19, 0] == pytest.approx(4.0) and rate[1, 19, 1] == pytest.approx(2.0)
    beta = prof.beta()
    np.testing.assert_allclose(beta[1, 19, 0], [0, 0.75, 0.25, 0])
    np.testing.assert_allclose(beta[3, 12, 2], 0.25)  # no trips: uniform


def test_missing_sector_is_filled_with_a_warning(tmp_path: Path, city: City) -> None:
    rows = [(d, s, a, b, 51) for d in range(1, 4) for s in (40, 76) for a in (10, 20, 40) for b in (10, 20, 40)]
    with pytest.warns(UserWarning, match=r"zone 30 \(Clinton West\)"):
        prof = read_zone_profile(write_profile(tmp_path / "p.csv", rows), city)
    assert prof.filled == (2,)
    rate = prof.rate()
    assert rate[1, 19, 2] > 0 and prof.trips[1, 76, :, 2].sum() > 0
    # The fallback is the adjacent sectors' trips per intersection (sector 2 borders 0 and 3).
    size = np.bincount(city.node_sector[city.pickup], minlength=4)
    per_node = np.mean([prof.trips[1, 76, n, :] / size[n] for n in (0, 3)], axis=0)
    np.testing.assert_allclose(prof.trips[1, 76, 2, [0, 1, 3]], per_node[[0, 1, 3]] * size[2])


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("dow,t_15min,puzone,dozone,n_trips\n1,76,10,20,5\n1,7x,10,20,5\n", r"p\.csv, row 3: field 't_15min': '7x'"),
        ("dow,t_15min,puzone,dozone,n_trips\n1,96,10,20,5\n", r"row 2: field 't_15min': .*0\.\.95"),
        ("dow,t_15min,puzone,dozone,n_trips\n5,6,10,20,5\n", r"row 2: field 'dow'"),
        ("dow,t_15min,puzone,dozone,n_trips\n1,6,10,20,-1\n", r"row 2: field 'n_trips'"),
        ("dow,t_15min,puzone,dozone,n_trips\n1,6,10,20,\n", r"row 2: field 'n_trips'"),
        ("dow,t_15min,pickup,dozone,n_trips\n1,6,10,20,4\n", r"p\.csv: missing column 'puzone'"),
    ],
)
def test_bad_rows_name_file_row_and_field(tmp_path: Path, city: City, text: str, match: str) -> None:
    path = tmp_path / "p.csv"
    path.write_text(text)
    with pytest.raises(DataError, match=match):
        read_zone_profile(path, city)


def test_unreadable_file(tmp_path: Path, city: City) -> None:
    with pytest.raises(DataError, match="p.csv"):
        read_zone_profile(tmp_path / "p.csv", city)


def test_world_base_demand_from_a_profile(tmp_path: Path, city: City) -> None:
    rows = [(d, s, a, b, 510) for d in range(5) for s in range(96) for a in ZONES for b in ZONES if a != b or s % 2]
    prof = read_zone_profile(write_profile(tmp_path / "p.csv", rows), city)
    H = hours_in_year(2022)
    dry = HourlyWeather(2022, np.full(H, 60.0), np.zeros(H), np.full(H, 5.0), "dry")
    w = synthetic_world(city, seed=1, weather=dry, zone_profile=prof, share=0.05)
    tuesday = dt.datetime(2022, 3, 8, 19)
    expected = prof.rate()[1, 19] * 0.05 * MONTH_FACTOR[2]
    np.testing.assert_allclose(w.base_rate()[w.hour_index(tuesday)], expected)
    np.testing.assert_allclose(w.od_matrix(dt.datetime(2022, 3, 8, 4)).sum(axis=1), 1.0)
    half = synthetic_world(city, seed=1, weather=dry, zone_profile=prof, share=0.025)
    np.testing.assert_allclose(half.base_rate(), w.base_rate() / 2)
    assert "share 0.05" in w.base_source


# ----------------------------------------------------------------- real files
needs_real = pytest.mark.skipif(not (TRIPS / "manhattan_zone_od_15min_2018.csv").exists(), reason="../shared/data not available")


@needs_real
def test_profile_table_matches_the_real_files() -> None:
    """PROFILE and MONTH_FACTOR in the code are what the real trip files give (see city.demand.profile)."""
    profile, months = derive_tables(
        TRIPS / "manhattan_zone_od_15min_2018.csv", TRIPS / "yellow_2016_sample.csv", TRIPS / "daily_trips_by_geography_2009_2017.csv"
    )
    np.testing.assert_allclose(profile, PROFILE, atol=0.0015)
    np.testing.assert_allclose(months, MONTH_FACTOR, atol=0.0015)


@needs_real
def test_real_zone_profile_on_the_nyc_map() -> None:
    from city.scenario import load_city

    city = load_city("nyc", SHARED)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prof = read_zone_profile(TRIPS / "manhattan_zone_od_15min_2018.csv", city)
    assert [city.sector_ids[s] for s in prof.filled] == [233]
    assert any("233" in str(w.message) for w in caught)
    at19 = prof.hourly()[:, 19]
    m = prof.filled[0]
    inside = at19.sum(axis=(1, 2)) - at19[:, m].sum(axis=1) - at19[:, :, m].sum(axis=1) + at19[:, m, m]
    assert inside.mean() == pytest.approx(REAL_TRIPS_19H, rel=0.01)
    assert prof.n_rows == 1_600_497
    # The 38 zones of the map keep the whole file's daily shape (PROFILE) to within 0.1 of the 19 h level.
    shape = prof.rate().sum(axis=2).mean(axis=0)
    np.testing.assert_allclose(shape / shape[19], PROFILE[:5].mean(axis=0) / PROFILE[:5, 19].mean(), atol=0.1)


def test_scenario_caches_the_profile(tmp_path: Path, city: City, monkeypatch: pytest.MonkeyPatch) -> None:
    from city.scenario import load_zone_profile

    monkeypatch.setenv("SURGE_CACHE", str(tmp_path / "cache"))
    path = write_profile(tmp_path / "p.csv", [(1, 76, 10, 20, 51), (2, 3, 20, 10, 102)])
    with pytest.warns(UserWarning, match="zone 30"):
        first = load_zone_profile(path, city)
    assert len(list((tmp_path / "cache").glob("zone-profile-*.npz"))) == 1
    with pytest.warns(UserWarning, match="zone 30"):
        again = load_zone_profile(path, city)
    np.testing.assert_array_equal(first.trips, again.trips)
    assert (first.filled, first.n_rows) == (again.filled, again.n_rows)


def test_share_flag_and_environment(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    from city.errors import ConfigError
    from city.scenario import SHARE_ENV, share_from_env
    from coordinator.cli import main

    monkeypatch.delenv(SHARE_ENV, raising=False)
    assert share_from_env() is None
    with pytest.raises(SystemExit) as exc:
        main(["demand", "--share", "1.5"])
    assert exc.value.code == 2 and "share 1.5 must be in (0, 1]" in capsys.readouterr().err
    monkeypatch.setenv(SHARE_ENV, "0.05")
    assert share_from_env() == 0.05
    monkeypatch.setenv(SHARE_ENV, "lots")
    with pytest.raises(ConfigError, match="SURGE_SHARE='lots'"):
        share_from_env()


def test_share_scales_the_synthetic_map_too(city: City) -> None:
    """On a map without a profile, share scales base demand and event trips alike (default: REF_RATE at 19 h)."""
    from city.demand.profile import FLEET_SHARE

    a = synthetic_world(city, seed=2)
    b = synthetic_world(city, seed=2, share=2 * FLEET_SHARE)
    np.testing.assert_allclose(b.expected_rate(), 2 * a.expected_rate())
