"""The rollout's values of the state after the horizon (``tail``, ``place``): exact against the simulator, off by default, and the same decisions in every runner."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agents import _kernels as K
from agents.base import EpisodeContext, make_policy
from agents.greedy import greedy_controls
from agents.ia import ia_controls
from agents._kernels import PLACE_SCALE
from agents.place_values import place_values
from agents.rollout import agent_costs, plan_agent
from agents.rollout_inputs import candidate_controls
from agents.rollout_config import RolloutConfig
from city.errors import ConfigError
from city.sim import FleetSim, Requests
from city.episode import run_episode
from tests.agents.test_rollout import DATE, StubWorld, context, grid_city, random_state, sampled_requests, uniform_forecast


def reference_tail_costs(ctx, committed: np.ndarray, agent: int) -> np.ndarray:
    """Every candidate's cost by the simulator with the real base policy, plus the tail from the simulated end state.

    The tail (:func:`agents._kernels._with_tail`): ``2 cycle (Σ g + tail g_H) - Σ_i (tail - a_i)²`` over the
    taxis the rollout simulates (free at some step of the horizon in some candidate), ``a_i`` taxi i's busy
    minutes left after the horizon plus its hops from its node (its drop-off when busy) to the nearest
    request still waiting, at most ``tail``.  With ``place``: ``100 Σ g + place Σ_i V(v_i)``, ``V`` the place
    values (:func:`agents.place_values.place_values`) and ``v_i`` the node of taxi i, over the taxis free after the horizon.
    """
    city, cfg, obs = ctx.city, ctx.config, ctx.obs
    here = int(obs.pos[agent])
    sectors = city.local_sectors(int(city.node_sector[here])) if cfg.scope == "local" else np.arange(city.n_sectors)
    tab = ctx.tables
    key = np.uint64(K.stream_key(cfg.seed, int(obs.t), agent))
    base = greedy_controls if cfg.base == "greedy" else ia_controls
    cands = candidate_controls(city, obs, agent)
    joints = np.repeat(ctx.base_controls[None, :], cands.size, axis=0)
    joints[:, :agent] = committed
    joints[:, agent] = cands
    _, _, tfree1 = K.step_zero(joints, obs.pos, obs.tau, obs.dest, obs.req_pickup, obs.req_dropoff, city.dist)
    simulated = np.flatnonzero(tfree1.min(axis=0) <= cfg.horizon)
    place = place_values(city, tab, sectors)
    out = np.zeros((cands.size, cfg.samples), dtype=np.int64)
    for s in range(cfg.samples):
        reqs = sampled_requests(ctx, sectors, key, s)
        for c, joint in enumerate(joints):
            sim = FleetSim(city, reqs, obs.pos)
            sim.state.t, sim.state.tau, sim.state.dest = obs.t, obs.tau.copy(), obs.dest.copy()
            g = total = sim.step(joint)
            for _ in range(cfg.horizon):
                g = sim.step(base(city, sim.observe()))
                total += g
            total += g
            st = sim.state
            waiting = reqs.pickup[sim.outstanding()]
            spared = 0
            for i in simulated:
                busy = int(st.tau[i])
                v = int(st.dest[i]) if busy else int(st.pos[i])
                d = int(city.dist[v, waiting].min()) if waiting.size else cfg.tail
                spared += (cfg.tail - min(cfg.tail, busy + d)) ** 2
            if cfg.place:
                ends = [int(st.pos[i]) for i in simulated if st.tau[i] == 0]
                out[c, s] = PLACE_SCALE * total + cfg.place * int(place[ends].sum())
            else:
                out[c, s] = 2 * cfg.cycle * (total + cfg.tail * g) - spared
    return out


@pytest.mark.parametrize("base,ce,scope", [("greedy", "limited", "local"), ("ia", "standard", "map"), ("greedy", "standard", "map"),
                                           ("ia", "limited", "local")])
@pytest.mark.parametrize("end", [{"tail": 9, "cycle": 4}, {"place": 3}])
def test_rollout_costs_with_a_tail_equal_the_simulator(base: str, ce: str, scope: str, end: dict) -> None:
    city = grid_city(5, 4)
    fc = uniform_forecast(city, [0.6, 1.4, 0.2, 2.0])
    checked = 0
    for seed in range(3):
        obs = random_state(city, np.random.default_rng(seed), taxis=6, requests=7)
        ctx = context(city, obs, fc, horizon=4, samples=12, base=base, ce=ce, scope=scope, seed=seed, **end)
        u = ctx.base_controls.copy()
        for agent in np.flatnonzero(obs.tau == 0):
            cands, costs = agent_costs(ctx, u[:agent], int(agent))
            ref = reference_tail_costs(ctx, u[:agent], int(agent))
            np.testing.assert_array_equal(costs, ref)
            best = plan_agent(ctx, u[:agent], int(agent))
            totals = ref.sum(axis=1)
            assert best == cands[int(np.flatnonzero(totals == totals.min())[0])]
            u[agent] = best
            checked += int(np.ptp(ref) > 0)
    assert checked > 0


def test_the_tail_moves_a_taxi_towards_requests_beyond_the_horizon() -> None:
    # A line: the taxi at 0, requests waiting at 12 and 13; with H = 3 no pickup is reachable, so
    # without a tail every control costs the same and the taxi stays; the tail sends it towards them.
    city = grid_city(16, 1, 2, 1)
    fc = uniform_forecast(city, [0.0, 0.0])
    from city.sim import Observation

    obs = Observation(5, np.array([0], np.int32), np.zeros(1, np.int32), np.full(1, -1, np.int32), np.arange(2),
                      np.array([12, 13], np.int32), np.array([15, 14], np.int32), np.array([1, 2], np.int32))
    plain = context(city, obs, fc, horizon=3, samples=4, seed=1)
    tailed = dataclasses.replace(plain, config=dataclasses.replace(plain.config, tail=20))
    none = np.empty(0, np.int32)
    assert plan_agent(plain, none, 0) == 0
    assert plan_agent(tailed, none, 0) == 1


def test_tail_is_off_by_default_and_checked() -> None:
    assert RolloutConfig().tail == 0
    city = grid_city(4, 4)
    assert make_policy("surge", city, forecast="true-rate").config.tail == 0
    assert make_policy("surge", city, forecast="true-rate", tail=30, cycle=8).config == dataclasses.replace(
        make_policy("surge", city, forecast="true-rate").config, tail=30, cycle=8)
    with pytest.raises(ConfigError, match="cycle at least 1"):
        RolloutConfig(tail=5, cycle=0)
    with pytest.raises(ConfigError, match="tail and place are alternatives"):
        RolloutConfig(tail=5, place=1)
    assert make_policy("surge", city, forecast="true-rate").config.place == 0


@pytest.mark.parametrize("options", [{"tail": 20}, {"tail": 20, "base": "ia", "adaptive": None}, {"place": 3}])
def test_same_seed_same_decisions_with_a_tail(options: dict) -> None:
    city = grid_city(6, 6)
    world = StubWorld(city, 20.0)
    rng = np.random.default_rng(11)
    n_req = 40
    reqs = Requests.sorted(rng.integers(0, 36, n_req), rng.integers(0, 36, n_req), rng.integers(0, 12, n_req))
    start = rng.integers(0, 36, 7).astype(np.int32)
    ctx = EpisodeContext(city=city, date=DATE, hour=19, minutes=12, seed=0, world=world)
    runs = [run_episode(city, make_policy("surge", city, forecast="true-rate", horizon=4, samples=50, seed=5, **options), reqs, start, ctx)
            for _ in range(2)]
    plain = run_episode(city, make_policy("surge", city, forecast="true-rate", horizon=4, samples=50, seed=5), reqs, start, ctx)
    assert runs[0].decisions_sha256 == runs[1].decisions_sha256
    assert runs[0].total_cost == runs[1].total_cost
    assert plain.decisions_sha256 != runs[0].decisions_sha256  # the tail changes what is decided


@pytest.mark.parametrize("end", [{"tail": 20, "cycle": 8}, {"place": 2}])
def test_exact_shortcuts_change_no_decision_with_a_tail(end: dict) -> None:
    """Every shortcut left on with a tail or place values (the skip and the shadow replays switch off) keeps the decisions of none."""
    from city.scenario import load_city
    from tests.agents.test_planning_speed import shortcuts_settled

    shortcuts_settled(load_city("synthetic"), range(1), cap=6, **end)


@pytest.mark.parametrize("end", [{"tail": 20}, {"place": 2}])
def test_waves_match_sequential_turns_with_a_tail(end: dict) -> None:
    from agents.rollout import DemandTables, prepare_step
    from agents.rollout_config import default_prune
    from agents.waves import plan_waves
    from city.scenario import load_city
    from tests.agents.test_planning_speed import H, SAMPLES, forecast, seeded_state

    city = load_city("synthetic")
    obs = seeded_state(city, 7, taxis=80)
    fc = forecast(city, np.random.default_rng(7))
    config = RolloutConfig(horizon=H, samples=SAMPLES, prune=default_prune(H), seed=1, adaptive=1.0, batch=16, cap=12, keep=2.0, **end)
    ctx = prepare_step(city, config, obs, DemandTables.build(city, fc, config.ce, config.seed), obs.t % 60)
    sequential = ctx.base_controls.copy()
    for agent in np.flatnonzero(obs.tau == 0):
        sequential[agent] = plan_agent(ctx, sequential[:agent], int(agent))
    assert plan_waves(city, obs, config.prune).critical_path < np.flatnonzero(obs.tau == 0).size
    policy = make_policy("surge", city, forecast="true-rate", workers=2, horizon=H, samples=SAMPLES, seed=1, batch=16, base="greedy",
                         scope="local", **end)
    assert policy.config == config
    u = ctx.base_controls.copy()
    policy._act_waves(ctx, u)
    np.testing.assert_array_equal(u, sequential)
