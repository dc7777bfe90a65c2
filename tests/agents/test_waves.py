"""Turns in dependency waves make the decisions of strictly sequential turns, over whole episodes on both maps.

The in-process policy with ``workers`` plans each wave's agents in threads
(:meth:`agents.rollout_policy.RolloutPolicy._act_waves`); the coordinator releases
the same waves over the bus (``tests/coordinator/test_runtime.py``).  Both read the one
graph of :func:`agents.waves.plan_waves`.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest

from agents.waves import plan_waves
from city.sim import FleetSim, decisions_hash
from coordinator.run_config import FleetConfig
from tests.conftest import SHARED_DATA

pytestmark = pytest.mark.usefixtures("compiled_kernels")


def _episode(cfg: FleetConfig, workers: int) -> tuple[str, list[tuple[int, int]]]:
    """The decisions hash of ``cfg``'s episode in-process, and each minute's (critical path, free taxis)."""
    scen, requests, start, context = cfg.instance()
    policy = dataclasses.replace(cfg, options={**cfg.options, "workers": workers}).make_policy(scen.city)
    policy.reset(context)
    sim = FleetSim(scen.city, requests, start)
    controls, shape = np.zeros((cfg.minutes, cfg.taxis), dtype=np.int32), []
    for t in range(cfg.minutes):
        obs = sim.observe()
        controls[t] = policy.act(obs)
        waves = plan_waves(scen.city, obs, policy.config.prune)
        shape.append((waves.critical_path, int(waves.agents.size)))
        sim.step(controls[t])
    return decisions_hash(controls), shape


@pytest.mark.parametrize("scenario", ["synthetic", "nyc"])
@pytest.mark.parametrize(("policy", "options"), [("surge", {"forecast": "true-rate"}), ("garces2023", {})])
def test_waves_keep_the_sequential_decisions_over_an_episode(scenario: str, policy: str, options: dict) -> None:
    data = None
    if scenario == "nyc":
        data = Path(os.environ.get("SURGE_TEST_DATA", SHARED_DATA))
        if not data.is_dir():
            pytest.skip("../shared/data not available")
    cfg = FleetConfig(scenario=scenario, data_dir=None if data is None else str(data), taxis=30, minutes=4, policy=policy,
                      options={**options, "samples": 24, "horizon": 5})
    sequential, shape = _episode(cfg, workers=1)
    in_waves, _ = _episode(cfg, workers=2)
    assert in_waves == sequential
    assert any(path < free for path, free in shape)  # agents did plan side by side
