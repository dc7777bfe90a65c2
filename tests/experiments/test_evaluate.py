"""The evaluation harness on the synthetic city: determinism and the oracle's bound."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from city.errors import ConfigError, DataError
from coordinator.experiments.analysis import (
    bootstrap_ci,
    compare,
    complete_seeds,
    format_comparison,
    oracle_exceptions,
    summarize,
)
from coordinator.experiments.evaluate import EvalConfig, borrowable, evaluate, instance_seed, parse_policy
from coordinator.experiments.results import read_results, upgrade, write_json

#: The route-planning oracle with a short search: these tests are about the harness, not the planner.
FAST = {"oracle": {"iters": 200}}


@pytest.fixture(scope="module")
def small_run() -> dict:
    cfg = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"], policy_options=FAST)
    return evaluate(cfg, progress=lambda _msg: None)


def test_same_seed_same_decisions(small_run: dict) -> None:
    cfg = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"], policy_options=FAST)
    again = evaluate(cfg, progress=lambda _msg: None)
    assert [e["decisions_sha256"] for e in again["episodes"]] == [e["decisions_sha256"] for e in small_run["episodes"]]
    assert [e["total_cost"] for e in again["episodes"]] == [e["total_cost"] for e in small_run["episodes"]]


def test_different_seeds_differ(small_run: dict) -> None:
    greedy = [e for e in small_run["episodes"] if e["policy"] == "greedy"]
    assert greedy[0]["decisions_sha256"] != greedy[1]["decisions_sha256"]


def test_parallel_workers_give_the_same_results(small_run: dict) -> None:
    cfg = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"], policy_options=FAST, jobs=2)
    par = evaluate(cfg, progress=lambda _msg: None)
    assert [e["decisions_sha256"] for e in par["episodes"]] == [e["decisions_sha256"] for e in small_run["episodes"]]


def test_rows_borrowed_from_an_earlier_run_are_those_a_fresh_run_computes(small_run: dict) -> None:
    cfg = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "surge:samples=8,forecast=true-rate"], policy_options=FAST)
    log: list[str] = []
    lent = evaluate(cfg, progress=log.append, borrow=small_run)
    fresh = evaluate(cfg, progress=lambda _msg: None)
    assert any("4 rows of the 2 instances to run are known already" in m for m in log)
    key = lambda e: (e["policy"], e["seed"], e["decisions_sha256"], e["total_cost"], e["oracle_cost"], e["oracle_auction_cost"], e["greedy_cost"])
    assert sorted(map(key, lent["episodes"])) == sorted(map(key, fresh["episodes"]))
    timed = {(e["policy"], e["seed"]): e["plan_seconds_per_step"] for e in small_run["episodes"]}
    assert all(e["plan_seconds_per_step"] == timed[(e["policy"], e["seed"])] for e in lent["episodes"] if e["policy"] != "surge:samples=8,forecast=true-rate")


def test_nothing_is_borrowed_across_different_settings(small_run: dict) -> None:
    assert len(borrowable(EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy"], policy_options=FAST), small_run)) == 2
    assert borrowable(EvalConfig(hours=[19], seeds=2, taxis=41, minutes=20, policies=["greedy"], policy_options=FAST), small_run) == {}
    assert borrowable(EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy"]), small_run) == {}
    other = {"oracle": {"iters": 200}, "ia": {"colour": 1}}
    assert borrowable(EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["ia"], policy_options=other), small_run) == {}


def test_oracle_is_cheapest_and_has_zero_overhead(small_run: dict) -> None:
    rows = {r["policy"]: r for r in summarize(small_run)}
    assert rows["oracle"]["total_cost"][0] < rows["greedy"]["total_cost"][0]
    assert rows["oracle"]["total_cost"][0] < rows["ia"]["total_cost"][0]
    assert rows["oracle"]["wait_overhead_per_served"][0] == 0.0
    assert rows["greedy"]["wait_overhead_per_served"][0] > 0.0


def test_gap_closed_is_measured_against_greedy_and_oracle(small_run: dict) -> None:
    rows = {r["policy"]: r for r in summarize(small_run)}
    assert rows["greedy"]["gap_closed"] == pytest.approx(0.0)
    assert rows["oracle"]["gap_closed"] == pytest.approx(1.0)
    eps = [e for e in small_run["episodes"] if e["policy"] == "ia"]
    greedy = sum(e["greedy_cost"] for e in eps)
    oracle = sum(e["oracle_cost"] for e in eps)
    assert rows["ia"]["gap_closed"] == pytest.approx((greedy - sum(e["total_cost"] for e in eps)) / (greedy - oracle))


def test_policy_specs_carry_options() -> None:
    assert parse_policy("surge:forecast=true-rate,samples=50,horizon=4") == ("surge", {"forecast": "true-rate", "samples": 50, "horizon": 4})
    assert parse_policy("greedy") == ("greedy", {})
    with pytest.raises(ConfigError, match="key=value"):
        parse_policy("surge:samples")
    cfg = EvalConfig(hours=[19], seeds=1, taxis=10, minutes=5, policies=["greedy:colour=red"])
    with pytest.raises(ConfigError, match="colour"):
        evaluate(cfg, progress=lambda _msg: None)


def test_resume_keeps_finished_instances(small_run: dict, tmp_path: Path) -> None:
    path = tmp_path / "r.json"
    one = EvalConfig(hours=[19], seeds=1, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"], policy_options=FAST)
    evaluate(one, progress=lambda _msg: None, checkpoint=path)
    first = json.loads(path.read_text())["episodes"]
    assert len(first) == 3
    msgs: list[str] = []
    two = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"], policy_options=FAST)
    doc = evaluate(two, progress=msgs.append, checkpoint=path, resume=True)
    assert msgs[0].startswith("resuming") and "[1/1]" in msgs[1] and len(msgs) == 2  # only seed 1 ran
    assert doc["episodes"][:3] == first
    assert [e["decisions_sha256"] for e in doc["episodes"]] == [e["decisions_sha256"] for e in small_run["episodes"]]
    other = EvalConfig(hours=[19], seeds=2, taxis=30, minutes=20, policies=["greedy", "ia", "oracle"], policy_options=FAST)
    with pytest.raises(DataError, match="taxis=40"):
        evaluate(other, progress=lambda _msg: None, checkpoint=path, resume=True)


def test_complete_seeds_drops_a_seed_missing_an_hour(small_run: dict) -> None:
    extra = {**small_run["episodes"][0], "hour": 21, "seed": 0}  # seed 0 is now at every hour, seed 1 at 19 h only
    doc = {**small_run, "episodes": small_run["episodes"] + [extra]}
    assert complete_seeds(doc)["episodes"] == [e for e in doc["episodes"] if e["seed"] == 0]
    assert complete_seeds(small_run)["episodes"] == small_run["episodes"]


def test_compare_pairs_instances(small_run: dict) -> None:
    rows = compare(small_run, "ia")
    assert [(r["against"], r["hour"], r["n"]) for r in rows] == [("greedy", 19, 2)]  # never against an oracle
    ia = [e for e in small_run["episodes"] if e["policy"] == "ia"]
    greedy = [e for e in small_run["episodes"] if e["policy"] == "greedy"]
    row = rows[0]
    assert row["wins"] == sum(a["total_cost"] < b["total_cost"] for a, b in zip(ia, greedy))
    assert row["cost_difference"] == pytest.approx(np.mean([a["total_cost"] - b["total_cost"] for a, b in zip(ia, greedy)]))
    over = [np.mean([e["wait_overhead_per_served"] for e in side]) for side in (ia, greedy)]
    assert row["overhead_reduction"] == pytest.approx(1 - over[0] / over[1])
    served = [np.mean([e["served"] for e in side]) for side in (ia, greedy)]
    assert row["served_change"] == pytest.approx(served[0] / served[1] - 1)
    assert row["below_oracle"] == sum(e["total_cost"] < e["oracle_cost"] for e in ia)
    diffs = [a["total_cost"] - b["total_cost"] for a, b in zip(ia, greedy)]
    assert row["ci95"] == list(bootstrap_ci(np.array(diffs)))
    assert row["ci95"][0] <= row["cost_difference"] <= row["ci95"][1]
    text = format_comparison(rows)
    assert "ia paired with each policy" in text and f" {row['wins']} / 2 " in text
    with pytest.raises(ConfigError, match="'surge' is not in the results"):
        compare(small_run, "surge")


def test_read_results_names_the_broken_episode(small_run: dict, tmp_path: Path) -> None:
    path = tmp_path / "r.json"
    doc = json.loads(json.dumps(small_run))
    del doc["episodes"][1]["served"]
    path.write_text(json.dumps(doc))
    with pytest.raises(DataError, match=r"r\.json: episode 1 has no 'served' field"):
        read_results(path)
    path.write_text("{")
    with pytest.raises(DataError, match="not JSON"):
        read_results(path)


def test_both_oracles_run_and_the_oracle_is_cheapest(small_run: dict) -> None:
    assert small_run["reference_oracle"] == "oracle"
    for e in small_run["episodes"]:
        assert e["oracle_cost"] <= e["oracle_auction_cost"]
    n, below = oracle_exceptions(small_run)
    assert n == 2 and below == []
    rows = {r["policy"]: r for r in summarize(small_run)}
    # The strong oracle's gap to greedy is at least the auction's, so a share of it is smaller in size, same sign.
    strong, auction = rows["ia"]["gap_closed"], rows["ia"]["gap_closed_auction"]
    assert auction is not None and strong * auction >= 0 and abs(auction) >= abs(strong)


def test_old_results_read_with_their_oracle_renamed(small_run: dict, tmp_path: Path) -> None:
    """A file from before the route planner: its 'oracle' was the auction, and it reads as oracle-auction."""
    old = json.loads(json.dumps(small_run))
    del old["reference_oracle"]
    cfg = old["config"]
    cfg["date"] = cfg.pop("dates")[0]
    for e in old["episodes"]:
        del e["date"], e["oracle_auction_cost"]
    old["episodes"][0]["policy"] = "oracle"
    path = tmp_path / "old.json"
    write_json(old, path)
    doc = read_results(path)
    assert doc["reference_oracle"] == "oracle-auction" and doc["config"]["dates"] == ["2022-11-17"]
    assert doc["episodes"][0]["policy"] == "oracle-auction"
    assert "oracle" not in doc["config"]["policies"] and "oracle-auction" in doc["config"]["policies"]
    assert all(e["date"] == "2022-11-17" and e["oracle_auction_cost"] == e["oracle_cost"] for e in doc["episodes"])
    with pytest.raises(DataError, match="'oracle' was the auction"):
        evaluate(EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"], policy_options=FAST),
                 progress=lambda _msg: None, checkpoint=path, resume=True)


def test_results_planned_before_surge_had_approximations_read_as_exact(small_run: dict, tmp_path: Path) -> None:
    """A file without ``surge_defaults`` was planned exactly over the greedy base: its surge labels read so, and no run of today's defaults takes their rows."""
    from agents.rollout_policy import EXACT, GREEDY_ROLLOUT

    assert small_run["surge_defaults"] == {"horizon": 20, "samples": 200, "base": "rebalance", "scope": "map", "cap": 12, "adaptive": 1.0,
                                           "batch": 50, "keep": 2.0}
    labels = ["surge:samples=8,forecast=true-rate", "surge:adaptive=3,cap=24,samples=8,forecast=true-rate"]
    old = json.loads(json.dumps(small_run))
    del old["surge_defaults"]
    old["config"]["policies"] += labels
    old["episodes"] += [{**e, "policy": label} for e in small_run["episodes"] if e["policy"] == "ia" for label in labels]
    path = tmp_path / "old.json"
    write_json(old, path)
    doc = read_results(path)
    greedy = {k: v for k, v in GREEDY_ROLLOUT.items() if k != "samples"}  # both labels set their samples
    assert doc["config"]["policy_options"] == {**FAST, labels[0]: {**greedy, **EXACT}, labels[1]: {**greedy, "batch": 100}}
    assert doc["surge_defaults"] == small_run["surge_defaults"]
    assert read_results(path) == doc and upgrade(doc) == doc  # read twice, brought up to date once

    # A file that records only the approximations planned over the greedy base, 10 minutes, local sampling.
    mid = {**old, "surge_defaults": {"cap": 24, "adaptive": 2.0, "batch": 50}}
    write_json(mid, path)
    assert read_results(path)["config"]["policy_options"] == {**FAST, labels[0]: {**greedy, "cap": 24, "adaptive": 2.0},
                                                              labels[1]: greedy}
    # A file that records today's defaults but keep planned without it: every surge label that does not set keep.
    nokeep = {**json.loads(json.dumps(old)), "surge_defaults": {k: v for k, v in small_run["surge_defaults"].items() if k != "keep"}}
    nokeep["config"]["policies"].append("surge:samples=8,keep=3,forecast=true-rate")
    write_json(nokeep, path)
    assert read_results(path)["config"]["policy_options"] == {**FAST, labels[0]: {"keep": None}, labels[1]: {"keep": None}}
    write_json(old, path)

    grid = dict(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle", *labels])
    today = EvalConfig(**grid, policy_options=FAST)
    assert {label for rows in borrowable(today, doc).values() for label in rows} == {"greedy", "ia", "oracle"}
    pinned = EvalConfig(**grid, policy_options={**FAST, labels[0]: {**greedy, **EXACT}, labels[1]: {**greedy, "batch": 100}})
    assert all(set(rows) >= set(labels) for rows in borrowable(pinned, doc).values())
    with pytest.raises(DataError, match="was written with policy_options="):
        evaluate(today, progress=lambda _msg: None, checkpoint=path, resume=True)


def test_instances_draw_their_own_rollout_seed() -> None:
    seeds = {instance_seed(d, h, s) for d in ("2022-11-17", "2022-10-06") for h in (17, 19) for s in range(5)}
    assert len(seeds) == 20
    assert instance_seed("2022-11-17", 19, 3) == instance_seed("2022-11-17", 19, 3)


def test_several_dates_pair_by_instance() -> None:
    cfg = EvalConfig(dates=["2022-11-17", "2022-10-06"], hours=[19], seeds=1, taxis=20, minutes=10, policies=["greedy", "ia"], policy_options=FAST)
    doc = evaluate(cfg, progress=lambda _msg: None)
    assert [(e["date"], e["policy"]) for e in doc["episodes"]] == [
        ("2022-11-17", "greedy"), ("2022-11-17", "ia"), ("2022-10-06", "greedy"), ("2022-10-06", "ia")]
    (row,) = compare(doc, "ia")
    assert row["n"] == 2 and row["dates"] == 2


def test_a_checkpoint_missing_some_rows_runs_only_those(small_run: dict, tmp_path: Path) -> None:
    cfg = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"], policy_options=FAST)
    path = tmp_path / "partial.json"
    write_json({**small_run, "episodes": [e for e in small_run["episodes"] if e["policy"] != "ia"]}, path)
    log: list[str] = []
    resumed = evaluate(cfg, progress=log.append, checkpoint=path, resume=True)
    assert any("0 instances done, 2 with some of their rows" in m for m in log)
    key = lambda e: (e["policy"], e["seed"], e["decisions_sha256"], e["total_cost"])
    assert list(map(key, resumed["episodes"])) == list(map(key, small_run["episodes"]))
    timed = {(e["policy"], e["seed"]): e["plan_seconds_per_step"] for e in small_run["episodes"]}
    assert all(e["plan_seconds_per_step"] == timed[(e["policy"], e["seed"])] for e in resumed["episodes"] if e["policy"] != "ia")
    assert read_results(path)["episodes"] == resumed["episodes"]


def test_a_resumed_run_may_add_policies_but_not_drop_them(small_run: dict, tmp_path: Path) -> None:
    path = tmp_path / "run.json"
    write_json({**small_run, "config": {**small_run["config"], "policies": ["greedy", "oracle"]},
                "episodes": [e for e in small_run["episodes"] if e["policy"] != "ia"]}, path)
    wider = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"], policy_options=FAST)
    log: list[str] = []
    resumed = evaluate(wider, progress=log.append, checkpoint=path, resume=True)
    assert any("2 with some of their rows" in m for m in log)
    key = lambda e: (e["policy"], e["seed"], e["decisions_sha256"], e["total_cost"])
    assert list(map(key, resumed["episodes"])) == list(map(key, small_run["episodes"]))
    narrower = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "oracle"], policy_options=FAST)
    with pytest.raises(DataError, match="was written with policies="):
        evaluate(narrower, progress=lambda _msg: None, checkpoint=path, resume=True)


def test_a_resumed_run_of_fewer_seeds_keeps_the_others_rows(small_run: dict, tmp_path: Path) -> None:
    """Adding a policy seed by seed (``--seeds 1`` on a file of 2) loses no row of the seeds it does not ask for."""
    path = tmp_path / "run.json"
    write_json({**small_run, "config": {**small_run["config"], "policies": ["greedy", "oracle"]},
                "episodes": [e for e in small_run["episodes"] if e["policy"] != "ia"]}, path)
    first = EvalConfig(hours=[19], seeds=1, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"], policy_options=FAST)
    evaluate(first, progress=lambda _msg: None, checkpoint=path, resume=True)
    kept = {(e["seed"], e["policy"]) for e in json.loads(path.read_text())["episodes"]}
    assert kept == {(0, "greedy"), (0, "ia"), (0, "oracle"), (1, "greedy"), (1, "oracle")}


def test_a_synthetic_run_resumes_whatever_data_path_its_file_recorded(small_run: dict, tmp_path: Path) -> None:
    """The synthetic city reads no data, so a file written with another ``--data`` path holds the same rows."""
    path = tmp_path / "run.json"
    write_json({**small_run, "config": {**small_run["config"], "data_dir": "/elsewhere/data"}}, path)
    cfg = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"], policy_options=FAST)
    log: list[str] = []
    resumed = evaluate(cfg, progress=log.append, checkpoint=path, resume=True)
    assert any("2 instances done" in m for m in log)
    assert [e["decisions_sha256"] for e in resumed["episodes"]] == [e["decisions_sha256"] for e in small_run["episodes"]]


def test_an_interrupted_instance_resumes_from_its_finished_episodes(small_run: dict, tmp_path: Path) -> None:
    from coordinator.experiments.evaluate import _instance
    from coordinator.experiments.results import episode_dir

    cfg = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"], policy_options=FAST)
    path = tmp_path / "run.json"
    folder = episode_dir(path)
    folder.mkdir()
    _instance(cfg, "2022-11-17", 19, 1, None, str(folder))  # seed 1 ran whole, but the run stopped before writing it
    files = sorted(folder.glob("2022-11-17-19-1-*.json"))
    assert len(files) == 3
    ia = next(f for f in files if json.loads(f.read_text())["row"]["policy"] == "ia")
    ia.unlink()  # stopped during ia: its row was never written
    (folder / "2022-11-17-19-0-broken.json").write_text("{not json")
    saved = {json.loads(f.read_text())["row"]["policy"]: json.loads(f.read_text())["row"] for f in files if f.exists()}
    log: list[str] = []
    resumed = evaluate(cfg, progress=log.append, checkpoint=path, resume=True)
    assert any("broken.json: not a finished episode" in m for m in log)
    assert any("2 finished episodes of unfinished instances are kept" in m for m in log)
    key = lambda e: (e["policy"], e["seed"], e["decisions_sha256"], e["total_cost"], e["oracle_cost"], e["greedy_cost"])
    assert list(map(key, resumed["episodes"])) == list(map(key, small_run["episodes"]))
    assert [e for e in resumed["episodes"] if e["seed"] == 1 and e["policy"] != "ia"] == [saved["greedy"], saved["oracle"]]  # kept, not rerun
    assert not folder.exists()  # every instance finished: their files, the broken one too, and the folder are gone
