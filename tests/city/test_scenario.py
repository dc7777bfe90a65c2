"""Scenarios end to end: the nyc map with a user's TLC trip records driving demand."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pytest

from city.demand import RecordedWorld
from city.scenario import load_scenario
from coordinator.experiments.evaluate import EvalConfig, evaluate
from tests.city.test_loaders import write_fhvhv


@pytest.fixture(scope="module")
def data_with_trips(tmp_path_factory: pytest.TempPathFactory, shared_data: Path) -> Path:
    """shared/data's map, weather and POIs (linked, not copied) plus a small HV-FHV parquet file."""
    root = tmp_path_factory.mktemp("data")
    nyc = root / "nyc"
    nyc.mkdir()
    for sub in ("street_network", "taxi_zones", "weather", "poi", "events"):
        (nyc / sub).symlink_to(shared_data / "nyc" / sub)
    (nyc / "trips").mkdir()
    rng = np.random.default_rng(7)
    zones = [161, 162, 163, 230, 186, 100, 48, 68]  # midtown zones of manhattan_below_60
    t0 = dt.datetime(2022, 11, 17, 19)
    rows = [
        (t0 + dt.timedelta(seconds=int(s)), t0 + dt.timedelta(seconds=int(s) + 300), int(rng.choice(zones)), int(rng.choice(zones)))
        for s in np.sort(rng.integers(0, 3600, 120))
    ]
    rows.append((t0 - dt.timedelta(hours=1), t0 - dt.timedelta(hours=1), 161, 1))  # to Newark: outside the map
    write_fhvhv(nyc / "trips" / "fhvhv_tripdata_2022-11.parquet", rows)
    return root


def test_nyc_replays_user_trip_records(data_with_trips: Path) -> None:
    scen = load_scenario("nyc", data_with_trips)
    assert isinstance(scen.world, RecordedWorld)
    counts = scen.world.hourly_counts()
    h = scen.world.hour_index(dt.datetime(2022, 11, 17, 19))
    assert counts[h].sum() == 120 and counts.sum() == 120
    req = scen.world.requests(dt.date(2022, 11, 17), 19)
    assert len(req) == 120
    sectors = {scen.city.sector_ids[s] for s in scen.city.node_sector[req.pickup]}
    assert sectors <= {161, 162, 163, 230, 186, 100, 48, 68}


def test_evaluate_runs_on_recorded_demand(data_with_trips: Path) -> None:
    cfg = EvalConfig(scenario="nyc", data_dir=str(data_with_trips), hours=[19], seeds=1, taxis=20, minutes=30, policies=["greedy", "oracle"])
    doc = evaluate(cfg, progress=lambda _m: None)
    assert doc["city"]["sectors"] == 38
    greedy, oracle = doc["episodes"]
    assert oracle["total_cost"] <= greedy["total_cost"]
