"""Your own city without New York: the shipped Gridville example runs, its world names itself, and any year works."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from city.demand import synthetic_world
from city.demand.naming import NEW_YORK, neutral
from city.errors import ConfigError
from city.scenario import load_scenario
from coordinator.cli import main

ROOT = Path(__file__).resolve().parents[2]
GRIDVILLE = ROOT / "examples" / "gridville" / "gridville.toml"
NEW_YORK_WORDS = ("Knicks", "NY ", "New York", "Hudson", "Garden Arena", "Harlem", "Celtics", "Big East")


def _all_text(world) -> str:
    events = " ".join(e.title + " " + e.description + " " + " ".join(e.reviews) for e in world.events)
    return events + " " + " ".join(v.name for v in world.venues)


def test_gridville_runs_surge_with_previous_hour_forecasts(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "gridville.json"
    assert main(["evaluate", "--scenario", str(GRIDVILLE), "--dates", "2023-11-16", "--hours", "19", "--seeds", "1", "--taxis", "4",
                 "--minutes", "5", "--policies", "greedy", "surge", "--forecast", "previous-hour", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert {e["policy"] for e in doc["episodes"]} == {"greedy", "surge"}
    assert {e["date"] for e in doc["episodes"]} == {"2023-11-16"}
    assert "gridville.toml: 64 intersections" in capsys.readouterr().out


def test_gridville_world_is_named_after_gridville_in_its_own_year() -> None:
    scen = load_scenario(str(GRIDVILLE))
    assert scen.world.year == 2023 and scen.spec is not None and scen.spec.event_names == "neutral"
    text = _all_text(scen.world)
    assert "Gridville Tech Expo 2023" in text and "Gridville Comets vs." in text
    assert [w for w in NEW_YORK_WORDS if w in text] == []
    assert load_scenario(str(GRIDVILLE), year=2025).world.year == 2025


def test_neutral_names_change_words_only() -> None:
    city = load_scenario("synthetic").city
    ny, own = synthetic_world(city, seed=1, naming=NEW_YORK), synthetic_world(city, seed=1, naming=neutral("lakeview"))
    np.testing.assert_array_equal(ny.expected_rate(), own.expected_rate())
    assert [(e.start, e.sector, e.attendance) for e in ny.events] == [(e.start, e.sector, e.attendance) for e in own.events]
    assert "Knicks vs. Celtics" in _all_text(ny) and [w for w in NEW_YORK_WORDS if w in _all_text(own)] == []
    assert "Lakeview Comets vs." in _all_text(own)


def test_any_year_evaluates(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    assert main(["evaluate", "--dates", "2024-07-04", "--hours", "12", "--seeds", "1", "--taxis", "5", "--minutes", "5",
                 "--policies", "greedy", "--json", str(out)]) == 0
    assert json.loads(out.read_text())["episodes"][0]["date"] == "2024-07-04"


@pytest.mark.parametrize(("line", "message"), [('event_names = "paris"', "event_names: 'paris' is not one of neutral, new-york"),
                                               ("year = 1800", "year: 1800 is not a calendar year")])
def test_bad_naming_or_year_is_one_line(tmp_path: Path, line: str, message: str) -> None:
    text = GRIDVILLE.read_text().replace("year = 2023", line)
    bad = GRIDVILLE.parent / f"bad-{abs(hash(line))}.toml"
    try:
        bad.write_text(text)
        with pytest.raises(ConfigError, match=message):
            load_scenario(str(bad))
    finally:
        bad.unlink()
