"""The PettingZoo environments: PettingZoo's own conformance and seed tests, and greedy through the AEC env = surge evaluate's greedy."""

from __future__ import annotations

import pytest

pytest.importorskip("pettingzoo")

from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test, seed_test  # noqa: E402

from agents.greedy import greedy_controls  # noqa: E402
from coordinator.experiments.evaluate import EvalConfig, evaluate  # noqa: E402
from coordinator.rl_env import EnvConfig, FleetAECEnv, FleetParallelEnv  # noqa: E402

SMALL = EnvConfig(taxis=6, minutes=12, hour=19)


def test_aec_env_passes_pettingzoo_api_test() -> None:
    api_test(FleetAECEnv(SMALL), num_cycles=200)


def test_parallel_env_passes_pettingzoo_parallel_api_test() -> None:
    parallel_api_test(FleetParallelEnv(SMALL), num_cycles=200)


def test_seeded_runs_repeat() -> None:
    seed_test(lambda: FleetAECEnv(SMALL), num_cycles=50)
    parallel_seed_test(lambda: FleetParallelEnv(SMALL), num_cycles=50)


def test_agent_selection_walks_the_free_taxis_in_order() -> None:
    env = FleetAECEnv(SMALL)
    env.reset(seed=1)
    minute, seen = env.sim.state.t, []
    free = [f"taxi_{i}" for i in range(SMALL.taxis) if env.sim.state.tau[i] == 0]
    while env.sim.state.t == minute:
        seen.append(env.agent_selection)
        obs = env.observe(env.agent_selection)
        assert obs["action_mask"][0] == 1
        env.step(0)
    assert seen == free


@pytest.mark.parametrize("seed", [0, 3])
def test_greedy_through_the_env_costs_what_evaluate_reports(seed: int) -> None:
    cfg = EnvConfig(taxis=10, minutes=30, hour=19)
    env = FleetAECEnv(cfg)
    env.reset(seed=seed)
    total, minute, joint = 0.0, None, None
    for agent in env.agent_iter():
        _, _, terminated, truncated, _ = env.last()
        if terminated or truncated:
            env.step(None)
            continue
        if env.sim.state.t != minute:
            minute, joint = env.sim.state.t, greedy_controls(env.episode.city, env.sim.observe())
        env.step(env.action_of(agent, int(joint[int(agent.split("_")[1])])))
        total += env.rewards["taxi_0"]
    doc = evaluate(EvalConfig(hours=[19], seeds=seed + 1, taxis=10, minutes=30, policies=["greedy"]), progress=lambda _m: None)
    expected = next(e["total_cost"] for e in doc["episodes"] if e["seed"] == seed and e["policy"] == "greedy")
    assert env.total_cost == expected == -total
