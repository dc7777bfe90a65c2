"""The warm-start protocol: each policy starts where its own previous hour left the fleet."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pytest

from agents.base import make_policy
from city.episode import EpisodeContext, episode_requests, initial_positions, run_episode
from city.errors import DataError
from city.scenario import load_scenario
from city.sim import FleetSim
from coordinator.experiments.evaluate import EvalConfig, borrowable, evaluate
from coordinator.experiments.warm_start import warm_start_positions, warm_up_hour

FAST = {"oracle": {"iters": 200}}
DATE = dt.date(2022, 11, 17)


@pytest.fixture(scope="module")
def scen():
    return load_scenario("synthetic", None, year=2022, seed=0)


def drive_hour(scen, name: str, date: dt.date, hour: int, taxis: int, seed: int) -> np.ndarray:
    """The warm-up hour run step by step here: the fleet's end, a taxi on a trip counted at its drop-off."""
    requests = episode_requests(scen.world, date, hour, 60)
    sim = FleetSim(scen.city, requests, initial_positions(scen.city, taxis, seed))
    policy = make_policy(name, scen.city)
    policy.reset(EpisodeContext(city=scen.city, date=date, hour=hour, minutes=60, seed=seed, world=scen.world))
    for _ in range(60):
        sim.step(policy.act(sim.observe()))
    assert (sim.state.tau > 0).any(), "the check needs a taxi on a trip at the end"
    return np.where(sim.state.tau > 0, sim.state.dest, sim.state.pos)


def test_warm_up_hour_is_the_hour_before() -> None:
    assert warm_up_hour(DATE, 19) == (DATE, 18)
    assert warm_up_hour(DATE, 0) == (dt.date(2022, 11, 16), 23)


@pytest.mark.parametrize("name", ["match", "rebalance"])
def test_warm_start_is_where_the_policy_left_the_previous_hour(scen, name: str) -> None:
    mine = drive_hour(scen, name, DATE, 18, taxis=12, seed=3)
    warm = warm_start_positions(scen.city, scen.world, lambda d, h: make_policy(name, scen.city), DATE, 19, 12, 3)
    np.testing.assert_array_equal(warm, mine)
    assert not np.array_equal(warm, initial_positions(scen.city, 12, 3))


def test_evaluate_runs_each_policy_from_its_own_warm_start(scen) -> None:
    cfg = EvalConfig(hours=[19], seeds=1, taxis=12, minutes=6, policies=["match", "rebalance"], policy_options=FAST, warm_start=True)
    doc = evaluate(cfg, progress=lambda _msg: None)
    assert doc["warm_start"] is True and doc["config"]["warm_start"] is True
    requests = episode_requests(scen.world, DATE, 19, 6)
    context = EpisodeContext(city=scen.city, date=DATE, hour=19, minutes=6, seed=0, world=scen.world)
    for row in doc["episodes"]:
        start = drive_hour(scen, row["policy"], DATE, 18, taxis=12, seed=0)
        expected = run_episode(scen.city, make_policy(row["policy"], scen.city), requests, start, context)
        assert row["decisions_sha256"] == expected.decisions_sha256
        assert row["total_cost"] == expected.total_cost


def test_warm_start_is_deterministic_per_seed(scen) -> None:
    cfg = EvalConfig(hours=[19], seeds=2, taxis=12, minutes=6, policies=["greedy", "match"], policy_options=FAST, warm_start=True)
    one, two = evaluate(cfg, progress=lambda _msg: None), evaluate(cfg, progress=lambda _msg: None)
    assert [e["decisions_sha256"] for e in one["episodes"]] == [e["decisions_sha256"] for e in two["episodes"]]
    starts = [warm_start_positions(scen.city, scen.world, lambda d, h: make_policy("match", scen.city), DATE, 19, 12, s) for s in (0, 0, 1)]
    np.testing.assert_array_equal(starts[0], starts[1])
    assert not np.array_equal(starts[0], starts[2])


def test_warm_and_cold_results_do_not_mix(tmp_path: Path) -> None:
    cold = EvalConfig(hours=[19], seeds=1, taxis=12, minutes=6, policies=["greedy"], policy_options=FAST)
    warm = EvalConfig(**{**cold.__dict__, "warm_start": True})
    cold_doc = evaluate(cold, progress=lambda _msg: None, checkpoint=tmp_path / "cold.json")
    warm_doc = evaluate(warm, progress=lambda _msg: None, checkpoint=tmp_path / "warm.json")
    assert cold_doc["warm_start"] is False
    with pytest.raises(DataError, match=r"cold\.json: holds cold-start results, this run is warm-start"):
        evaluate(warm, progress=lambda _msg: None, checkpoint=tmp_path / "cold.json", resume=True)
    with pytest.raises(DataError, match=r"warm\.json: holds warm-start results, this run is cold-start"):
        evaluate(cold, progress=lambda _msg: None, checkpoint=tmp_path / "warm.json", resume=True)
    assert borrowable(warm, cold_doc) == {} and borrowable(cold, warm_doc) == {}
    assert len(borrowable(warm, warm_doc)) == 1
