"""The RL example: Stable-Baselines3's PPO trains a shared policy on the parallel env (tiny size) and is judged against greedy."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("supersuit")

from coordinator.experiments.evaluate import EvalConfig, evaluate
from coordinator.experiments.rl_train import TrainConfig, greedy_policy, play

ROOT = Path(__file__).resolve().parents[2]


def test_example_trains_and_writes_its_curve(tmp_path: Path) -> None:
    cmd = [sys.executable, "examples/rl_shared_policy.py", "--taxis", "4", "--minutes", "8", "--timesteps", "640",
           "--eval-every", "320", "--eval-seeds", "2", "--out", str(tmp_path)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "UserWarning" not in done.stderr
    doc = json.loads((tmp_path / "rl-training.json").read_text())
    assert {"command", "date", "machine"} <= doc.keys()
    assert [p["timesteps"] for p in doc["curve"]][0] < 320 < doc["curve"][-1]["timesteps"]
    assert len(doc["episodes"]["ppo"]) == len(doc["episodes"]["greedy"]) == 2
    assert doc["ppo_vs_greedy"]["n"] == 2
    assert (tmp_path / "rl-training.png").read_bytes()[:4] == b"\x89PNG"
    assert "PPO - greedy" in done.stdout


def test_greedy_through_the_parallel_env_costs_what_evaluate_reports() -> None:
    cfg = TrainConfig(taxis=10, minutes=30, eval_dates=("2022-11-17",), eval_seeds=(0, 1))
    costs = [r["total_cost"] for r in play(cfg, greedy_policy)]
    doc = evaluate(EvalConfig(hours=[19], seeds=2, taxis=10, minutes=30, policies=["greedy"]), progress=lambda _m: None)
    assert costs == [e["total_cost"] for e in sorted(doc["episodes"], key=lambda e: e["seed"])]
