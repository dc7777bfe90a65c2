"""Decision hashes pinned from committed results: code moves and refactors must not change a decision.

Each case is a row of ``benchmarks/paper-protocol`` results (the quick protocol on the embedded
synthetic city, 2022-11-17 19 h, seed 0, 100 taxis, 60 minutes), rerun here with the options the
results file recorded, ``surge`` pinned to exact planning as the file was planned.
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
    options = {label: {"samples": 100, **pinned_options(label)} for label in labels if label not in ("greedy", "ia")}
    cfg = EvalConfig(scenario="synthetic", dates=["2022-11-17"], hours=[19], seeds=1, taxis=100, minutes=60,
                     policies=labels, policy_options=options)
    (rows,) = run_instances(cfg, [("2022-11-17", 19, 0)])
    assert {r["policy"]: r["decisions_sha256"][:16] for r in rows} == PINNED
