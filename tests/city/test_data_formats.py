"""Every example input file of docs/data.md reads with the reader that documents it."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

from city.io.events import read_events, read_reviews
from city.io.occupancy import read_occupancy_csv
from city.io.poi import read_poi_csv
from city.io.street_map import zone_ids_in_group
from city.io.trips import read_zone_profile
from city.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[2]
FORMATS = ROOT / "examples" / "data-formats"
GRIDVILLE = ROOT / "examples" / "gridville" / "gridville.toml"


def test_event_files_read_in_the_scenario_timezone() -> None:
    city = load_scenario(str(GRIDVILLE)).city
    csv = read_events(FORMATS / "events.csv", city, FORMATS / "reviews.csv", tz="America/Chicago")
    assert [e.event_id for e in csv] == ["e1", "e2"]
    assert csv[1].start == dt.datetime(2023, 11, 16, 19, 0) and len(csv[0].reviews) == 2
    [market] = read_events(FORMATS / "events.json", city, tz="America/Chicago")
    assert market.start == dt.datetime(2023, 12, 2, 10, 0) and market.reviews == ("Cosy and crowded",)
    assert len(read_reviews(FORMATS / "reviews.csv")["e1"]) == 2


def test_the_other_example_files_read() -> None:
    city = load_scenario(str(GRIDVILLE)).city
    pois = read_poi_csv(FORMATS / "pois.csv", borough=None, types={"inn": "hotel", "shop": "retail", "diner": "restaurant"})
    assert sorted(pois.kind.tolist()) == ["hotel", "restaurant", "retail"]
    assert read_occupancy_csv(FORMATS / "occupancy.csv")["hotel"]["sunday"][12] == 0.8
    profile = read_zone_profile(FORMATS / "zone_od_15min.csv", city)
    assert profile.trips.sum() > 0
    assert zone_ids_in_group(FORMATS / "zone_groups.csv", "group", "north") == [3, 4]
