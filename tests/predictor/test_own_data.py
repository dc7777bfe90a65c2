"""Your own data: one timezone rule for events (the scenario's), what training read, and a model's own events said aloud."""

from __future__ import annotations

import argparse
import datetime as dt
import shutil
from pathlib import Path

import pytest

from city.scenario import load_scenario, read_scenario_events, scenario_spec, scenario_timezone
from predictor.features import active_events
from predictor.inputs import load_world

ROOT = Path(__file__).resolve().parents[2]
GRIDVILLE = ROOT / "examples" / "gridville"
CHICAGO_EVENT = ("event_id,title,description,category,start,end,lat,lon\n"
                 "e1,Late show,A concert,concerts,2022-11-18T01:00:00Z,2022-11-18T03:00:00Z,41.804,-87.694\n")


@pytest.fixture(scope="module")
def chicago(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Gridville (America/Chicago) with an events file whose one event starts at 01:00 UTC."""
    root = tmp_path_factory.mktemp("chicago")
    shutil.copytree(GRIDVILLE, root, dirs_exist_ok=True)
    (root / "events.csv").write_text(CHICAGO_EVENT)
    path = root / "gridville.toml"
    path.write_text(path.read_text() + '\n[events]\nfile = "events.csv"\nkind = "listing"\n')
    return path


def test_an_event_in_utc_lands_at_the_same_local_hour_in_the_world_and_the_predictor(chicago: Path) -> None:
    assert scenario_timezone(str(chicago)) == "America/Chicago"
    local = dt.datetime(2022, 11, 17, 19, 0)
    spec = scenario_spec(str(chicago))
    city = load_scenario(str(chicago), year=2022).city
    [in_world] = read_scenario_events(spec, city)
    world, _ = load_world(str(chicago), None, year=2022, events=chicago.parent / "events.csv")
    [in_predictor] = world.events
    assert in_world.start == in_predictor.start == local
    assert [e.event_id for e in active_events(world, local, lead=0, lag=0)] == ["e1"]
    assert active_events(world, local + dt.timedelta(hours=1 + 2), lead=0, lag=0) == []


def test_training_says_what_it_read(chicago: Path) -> None:
    from predictor.jobs import input_lines

    world, trips = load_world(str(chicago), None, year=2022, events=chicago.parent / "events.csv")
    args = argparse.Namespace(events=str(chicago.parent / "events.csv"), reviews=None, trips=None)
    events, trip_line = input_lines(world, trips, args, "America/Chicago")
    assert events == f"events: 1 from {args.events}, local times in America/Chicago"
    assert trip_line == "trips: none read; hourly counts are the scenario world's own"
    own, _ = load_world("synthetic", None)
    assert input_lines(own, None, argparse.Namespace(events=None, reviews=None, trips=None), "America/New_York")[0].startswith(
        "events: the scenario world's own (")
