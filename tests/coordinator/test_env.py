"""The PettingZoo environments: PettingZoo's own conformance, seed and state tests on both envs and their wrapper conversions, rendering, and greedy through the AEC env = surge evaluate's greedy."""

from __future__ import annotations

import pytest

pytest.importorskip("pettingzoo")

import warnings

import numpy as np
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test, seed_test
from pettingzoo.test.state_test import state_test
from pettingzoo.utils.conversions import aec_to_parallel, parallel_to_aec

from city.errors import ConfigError

from agents.greedy import greedy_controls
from coordinator.experiments.evaluate import EvalConfig, evaluate
from coordinator.rl_env import EnvConfig, FleetAECEnv, FleetParallelEnv
from coordinator.rl_env_view import display_available

SMALL = EnvConfig(taxis=6, minutes=12, hour=19)
TWENTY = EnvConfig(taxis=20, minutes=30, hour=19)
#: The two warnings PettingZoo's tests draw for any action-mask Dict observation space.
DICT_SPACE_WARNINGS = {
    "Observation is not a NumPy array",
    "Observation space for each agent probably should be gymnasium.spaces.box or gymnasium.spaces.discrete",
}

ENVS = {
    "aec": lambda: FleetAECEnv(TWENTY),
    "parallel": lambda: FleetParallelEnv(TWENTY),
    "aec_to_parallel": lambda: aec_to_parallel(FleetAECEnv(TWENTY)),
    "parallel_to_aec": lambda: parallel_to_aec(FleetParallelEnv(TWENTY)),
}


def _warnings_besides_dict_space(run) -> set[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run()
    return {str(w.message) for w in caught} - DICT_SPACE_WARNINGS


@pytest.mark.parametrize("name", list(ENVS))
def test_pettingzoo_api_and_seed_tests_at_20_taxis(name: str) -> None:
    make = ENVS[name]
    is_aec = name in ("aec", "parallel_to_aec")

    def run() -> None:
        if is_aec:
            api_test(make(), num_cycles=60)
            seed_test(make, num_cycles=30)
        else:
            parallel_api_test(make(), num_cycles=60)
            parallel_seed_test(make, num_cycles=30)

    assert _warnings_besides_dict_space(run) == set()


def test_state_is_a_box_for_centralised_critics() -> None:
    assert _warnings_besides_dict_space(lambda: state_test(FleetAECEnv(TWENTY), FleetParallelEnv(TWENTY))) == set()
    env = FleetParallelEnv(TWENTY)
    env.reset(seed=2)
    s0 = env.state()
    assert s0.shape == env.state_space.shape and env.state_space.contains(s0)
    env.step({a: 0 for a in env.agents})
    assert not np.array_equal(env.state(), s0)
    assert aec_to_parallel(FleetAECEnv(TWENTY)).state_space == env.state_space


def test_aec_and_wrapped_parallel_agree_minute_by_minute() -> None:
    """aec_to_parallel of the AEC env plays the same minutes at the same cost as the native parallel env."""
    wrapped, native = aec_to_parallel(FleetAECEnv(TWENTY)), FleetParallelEnv(TWENTY)
    wrapped.reset(seed=4)
    obs, _ = native.reset(seed=4)
    rng = np.random.default_rng(0)
    while native.agents:
        actions = {a: int(rng.choice(np.flatnonzero(obs[a]["action_mask"]))) for a in native.agents}
        _, r_w, *_ = wrapped.step(actions)
        obs, r_n, *_ = native.step(actions)
        assert r_w["taxi_0"] == r_n["taxi_0"]
        assert np.array_equal(wrapped.state(), native.state())


@pytest.mark.parametrize("make", [FleetAECEnv, FleetParallelEnv])
def test_render_rgb_array_draws_the_map(make) -> None:
    env = make(TWENTY, render_mode="rgb_array")
    env.reset(seed=0)
    image = env.render()
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 10
    assert make(TWENTY).render() is None
    env.close()


def test_render_human_without_a_display_is_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if display_available():
        pytest.skip("this platform always has a display")
    with pytest.raises(ConfigError, match="needs a display"):
        FleetParallelEnv(SMALL, render_mode="human")
    with pytest.raises(ConfigError, match="not one of"):
        FleetAECEnv(SMALL, render_mode="ansi")


def test_agent_selection_walks_every_taxi_in_order_and_busy_taxis_have_one_slot() -> None:
    env = FleetAECEnv(SMALL)
    env.reset(seed=1)
    for _ in range(5):
        minute, seen = env.sim.state.t, []
        while env.sim.state.t == minute:
            agent = env.agent_selection
            seen.append(agent)
            mask = env.observe(agent)["action_mask"]
            assert mask[0] == 1
            busy = env.sim.state.tau[int(agent.split("_")[1])] > 0
            if busy:
                assert mask.sum() == 1
            actions = np.flatnonzero(mask)
            env.step(int(actions[-1]))
        assert seen == [f"taxi_{i}" for i in range(SMALL.taxis)]


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
