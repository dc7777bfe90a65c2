"""The evaluation harness on the synthetic city: determinism and the oracle's bound."""

from __future__ import annotations

import pytest

from coordinator.evaluate import EvalConfig, evaluate, summarize


@pytest.fixture(scope="module")
def small_run() -> dict:
    cfg = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"])
    return evaluate(cfg, progress=lambda _msg: None)


def test_same_seed_same_decisions(small_run: dict) -> None:
    cfg = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"])
    again = evaluate(cfg, progress=lambda _msg: None)
    assert [e["decisions_sha256"] for e in again["episodes"]] == [e["decisions_sha256"] for e in small_run["episodes"]]
    assert [e["total_cost"] for e in again["episodes"]] == [e["total_cost"] for e in small_run["episodes"]]


def test_different_seeds_differ(small_run: dict) -> None:
    greedy = [e for e in small_run["episodes"] if e["policy"] == "greedy"]
    assert greedy[0]["decisions_sha256"] != greedy[1]["decisions_sha256"]


def test_parallel_workers_give_the_same_results(small_run: dict) -> None:
    cfg = EvalConfig(hours=[19], seeds=2, taxis=40, minutes=20, policies=["greedy", "ia", "oracle"], jobs=2)
    par = evaluate(cfg, progress=lambda _msg: None)
    assert [e["decisions_sha256"] for e in par["episodes"]] == [e["decisions_sha256"] for e in small_run["episodes"]]


def test_oracle_is_cheapest_and_has_zero_overhead(small_run: dict) -> None:
    rows = {r["policy"]: r for r in summarize(small_run)}
    assert rows["oracle"]["total_cost"][0] < rows["greedy"]["total_cost"][0]
    assert rows["oracle"]["total_cost"][0] < rows["ia"]["total_cost"][0]
    assert rows["oracle"]["wait_overhead_per_served"][0] == 0.0
    assert rows["greedy"]["wait_overhead_per_served"][0] > 0.0
