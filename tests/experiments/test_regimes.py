"""The per-regime report: surge against the strongest practical baseline per map × hour × fleet size, and its forecasts."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from coordinator.experiments.evaluate import EvalConfig, evaluate
from coordinator.experiments.regimes import forecast_labels, format_regimes, plot_regimes, regime_rows
from coordinator.experiments.results import write_json

POLICIES = ["match", "rebalance", "surge:samples=4", "surge:samples=4,forecast=true-rate"]
OPTIONS = {"oracle": {"iters": 100}, "surge:samples=4": {"forecast": "previous-hour"}, "rebalance": {"forecast": "previous-hour"}}


@pytest.fixture(scope="module")
def docs() -> list[dict]:
    return [evaluate(EvalConfig(hours=[19], seeds=2, taxis=n, minutes=10, policies=POLICIES, policy_options=OPTIONS),
                     progress=lambda _msg: None) for n in (8, 12)]


def cost(doc: dict, label: str) -> np.ndarray:
    return np.array([e["total_cost"] for e in sorted(doc["episodes"], key=lambda e: e["seed"]) if e["policy"] == label])


def test_a_row_per_regime_against_the_cheaper_baseline(docs: list[dict]) -> None:
    rows = regime_rows(docs, policy="surge:samples=4")
    assert [(r["scenario"], r["hour"], r["taxis"]) for r in rows] == [("synthetic", 19, 8), ("synthetic", 19, 12)]
    for doc, r in zip(docs, rows):
        best = min(("match", "rebalance"), key=lambda p: (cost(doc, p).mean(), p))
        diff = cost(doc, "surge:samples=4") - cost(doc, best)
        assert r["strongest"] == best and r["n"] == 2 and r["warm_start"] is False
        assert r["cost_difference"] == pytest.approx(diff.mean())
        assert r["wins"] == int((diff < 0).sum())
        assert r["ci95"][0] <= r["cost_difference"] <= r["ci95"][1]
        (other,) = r["forecast_differences"]
        assert other["forecast"] == "true-rate" and other["against"] == "previous-hour"
        assert other["cost_difference"] == pytest.approx((cost(doc, POLICIES[3]) - cost(doc, POLICIES[2])).mean())


def test_only_labels_that_differ_in_their_forecast_are_compared(docs: list[dict]) -> None:
    assert forecast_labels(docs[0], "surge:samples=4") == {"true-rate": "surge:samples=4,forecast=true-rate"}
    assert forecast_labels(docs[0], "surge:samples=5") == {}


def test_table_figure_and_command(docs: list[dict], tmp_path: Path) -> None:
    rows = regime_rows(docs, policy="surge:samples=4")
    text = format_regimes(rows)
    assert "true-rate − previous-hour" in text and len(text.splitlines()) == 2 + len(rows)
    plot_regimes(rows, tmp_path / "fig.png")
    assert (tmp_path / "fig.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    alone = [{**r, "forecast_differences": []} for r in rows]  # no other forecast: the top row of the figure alone
    plot_regimes(alone, tmp_path / "alone.png")
    import matplotlib.image

    assert matplotlib.image.imread(tmp_path / "alone.png").shape[0] < matplotlib.image.imread(tmp_path / "fig.png").shape[0]
    files = []
    for k, doc in enumerate(docs):
        write_json(doc, tmp_path / f"r{k}.json")
        files.append(str(tmp_path / f"r{k}.json"))
    proc = subprocess.run([sys.executable, "-m", "coordinator.cli", "report", "--regimes", *files, "--policy", "surge:samples=4",
                           "--json", str(tmp_path / "out.json")], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    out = json.loads((tmp_path / "out.json").read_text())
    assert out["command"].startswith("surge report --regimes") and out["date"] and out["machine"]
    assert [r["taxis"] for r in out["regimes"]] == [8, 12]
