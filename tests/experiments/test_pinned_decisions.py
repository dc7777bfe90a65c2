"""Decision hashes pinned from committed results: code moves and refactors must not change a decision.

Each case is a row of ``benchmarks/paper-protocol`` results (the quick protocol on the embedded
synthetic city, 2022-11-17 19 h, seed 0, 100 taxis, 60 minutes), rerun here with the options the
results file recorded, ``surge`` pinned to the paper's configuration as the file was planned.
"""

from __future__ import annotations

import pytest
from coordinator.experiments.evaluate import EvalConfig, run_instances

from agents.rollout_policy import pinned_options

PINNED = {
    "greedy": "59dd67c654fc4a08",
    "ia": "8626b571f7f244cd",
    "garces2023": "03d0df943a9bc263",
    "surge:forecast=true-rate": "c67abaf6e2e6503b",
}


@pytest.mark.timeout(900)
def test_committed_decisions_reproduce() -> None:
    labels = list(PINNED)
    options = {label: {**pinned_options(label), "samples": 100} for label in labels if label not in ("greedy", "ia")}
    cfg = EvalConfig(scenario="synthetic", dates=["2022-11-17"], hours=[19], seeds=1, taxis=100, minutes=60,
                     policies=labels, policy_options=options)
    (rows,) = run_instances(cfg, [("2022-11-17", 19, 0)])
    assert {r["policy"]: r["decisions_sha256"][:16] for r in rows} == PINNED


@pytest.mark.timeout(900)
def test_default_surge_plans_as_the_committed_rollout_over_rebalance_with_keep() -> None:
    """A bare ``surge`` label makes the decisions committed for the rollout over ``rebalance`` with ``keep=2``.

    The row is that variant's on the paper's date (synthetic city, 19 h, seed 0, previous-hour demand),
    whose label names every option.
    """
    import datetime as dt
    from pathlib import Path

    from agents.base import EpisodeContext, make_policy
    from city.episode import episode_requests, initial_positions, run_episode
    from city.scenario import load_scenario
    from coordinator.experiments.evaluate import instance_seed
    from coordinator.experiments.results import read_results

    label = "surge:base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1,keep=2"
    path = Path(__file__).parents[2] / "benchmarks/practice-baselines/test-2022-11-17/keep-synthetic.json"
    doc = read_results(path)
    assert doc["config"]["policy_options"][label] == {"forecast": "previous-hour"}  # nothing pinned: it is exactly today's default
    row = next(e for e in doc["episodes"] if e["policy"] == label and (e["date"], e["hour"], e["seed"]) == ("2022-11-17", 19, 0))
    date = dt.date(2022, 11, 17)
    scen = load_scenario("synthetic")
    policy = make_policy("surge", scen.city, forecast="previous-hour", seed=instance_seed(date, 19, 0))
    result = run_episode(scen.city, policy, episode_requests(scen.world, date, 19, 60), initial_positions(scen.city, 100, 0),
                         EpisodeContext(scen.city, date, 19, 60, 0, scen.world))
    assert (result.decisions_sha256, result.total_cost) == (row["decisions_sha256"], row["total_cost"])
