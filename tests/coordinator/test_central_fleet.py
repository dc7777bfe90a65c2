"""Centrally computed policies (``match``, ``rebalance``) in the distributed runtime: one process per taxi, the in-process decisions."""

from __future__ import annotations

import pytest

from city.errors import ConfigError
from coordinator.fleet import in_process, run_local_fleet
from coordinator.run_config import FleetConfig
from coordinator.runtime import Coordinator


@pytest.mark.parametrize(("policy", "options"), [("match", {}), ("rebalance", {"forecast": "true-rate", "lookahead": 6})])
def test_a_central_policy_runs_in_the_fleet_with_the_in_process_decisions(policy: str, options: dict) -> None:
    """The coordinator computes the joint control and sends it with the state; each taxi's process answers its turn with its entry."""
    cfg = FleetConfig(run=f"central-{policy}", taxis=4, minutes=8, policy=policy, options=options, deadline_s=60, join_timeout_s=300)
    dist = run_local_fleet(cfg, secure=False, agent_threads=1)
    ref = in_process(cfg)
    assert dist["fallbacks"] == 0 and dist["agents_exit_codes"] == [0, 0, 0, 0]
    assert sum(dist["planned_per_agent"]) == sum(dist["free_per_minute"]) > 0  # every free taxi answered every turn itself
    assert dist["decisions_sha256"] == ref["decisions_sha256"]
    assert dist["total_cost"] == ref["total_cost"] and dist["served"] == ref["served"]


def test_a_central_policy_takes_no_predictor_service_and_other_policies_are_refused() -> None:
    with pytest.raises(ConfigError, match="computed by the coordinator.*predictor service serves rollout agents only"):
        Coordinator(FleetConfig(run="central-predictor", taxis=2, minutes=2, policy="rebalance", predictor=True), progress=False)
    with pytest.raises(ConfigError, match="runs rollout policies .* and centrally computed ones"):
        Coordinator(FleetConfig(run="central-greedy", taxis=2, minutes=2, policy="greedy"), progress=False)
