"""``surge`` variants in the distributed fleet (a tail, place values, the rebalance base, keeping the base's control): one process per taxi over a real zenoh router, the in-process decisions."""

from __future__ import annotations

import dataclasses

import pytest

from coordinator.fleet import in_process, run_local_fleet
from coordinator.run_config import FleetConfig

pytestmark = pytest.mark.usefixtures("compiled_kernels")


@pytest.mark.parametrize("end", [{"tail": 20, "cycle": 8}, {"place": 2}, {"base": "rebalance", "keep": None}, {"base": "rebalance", "keep": 2.0}])
def test_distributed_surge_variants_make_the_in_process_decisions(end: dict) -> None:
    """The variant travels in the run spec's rollout settings; every agent plans with it, the place
    values from the forecast of its own sectors, the rebalance base with the targets each state carries."""
    cfg = FleetConfig(run="same-surge-tail", taxis=3, minutes=8, policy="surge",
                      options={"forecast": "true-rate", "samples": 100, **end}, deadline_s=120,
                      join_timeout_s=300, predictor=False)
    dist = run_local_fleet(cfg, secure=False, agent_threads=1)
    ref = in_process(cfg)
    assert dist["fallbacks"] == 0 and dist["agents_exit_codes"] == [0, 0, 0]
    assert sum(dist["planned_per_agent"]) > 0
    assert dist["decisions_sha256"] == ref["decisions_sha256"]
    assert dist["total_cost"] == ref["total_cost"] and dist["served"] == ref["served"]
    if end.get("keep"):  # the agents kept base controls that the rollout alone would have left
        plain = in_process(dataclasses.replace(cfg, options={**cfg.options, "keep": None}))
        assert plain["decisions_sha256"] != ref["decisions_sha256"]
