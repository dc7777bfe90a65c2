"""The ``rebalance`` rollout base: exact against the simulator, its minute equals ``rebalance``'s, deterministic."""

from __future__ import annotations

import numpy as np
import pytest

from agents import _kernels as K
from agents.base import make_policy
from agents.ia import ia_controls
from agents.rebalance import rebalance_plan, sector_anchors
from agents.rollout import (
    DemandTables,
    HourInputs,
    RolloutConfig,
    agent_costs,
    base_controls,
    plan_agent,
    prepare_step,
)
from agents.rollout_inputs import candidate_controls
from city.errors import ConfigError
from city.sim import FleetSim, Requests
from city.episode import EpisodeContext, run_episode
from tests.agents.test_rollout import DATE, StubWorld, grid_city, random_state, sampled_requests, uniform_forecast


def rebalance_context(city, obs, fc, **cfg):
    config = RolloutConfig(base="rebalance", **cfg)
    return prepare_step(city, config, obs, DemandTables.build(city, fc, config.ce, config.seed), obs.t % 60, hour=HourInputs.of(city, fc))


def homing_controls(city, obs, home: np.ndarray) -> np.ndarray:
    """The simulated ``rebalance`` base in plain numpy: ``ia``, and an unmatched free taxi one hop toward its target."""
    u = ia_controls(city, obs).astype(np.int64)
    go = (obs.tau == 0) & (u == obs.pos) & (home >= 0) & (obs.pos != home)
    u[go] = city.next_hop[obs.pos[go], home[go]]
    return u


def reference_costs(ctx, committed: np.ndarray, agent: int) -> np.ndarray:
    """Every candidate and sample run by ``FleetSim``: the decision minute, then ``H`` minutes of :func:`homing_controls`.

    A taxi's target is dropped once it picks up (its ``tau`` turns positive from zero).
    """
    city, cfg, obs = ctx.city, ctx.config, ctx.obs
    here = int(obs.pos[agent])
    sectors = city.local_sectors(int(city.node_sector[here])) if cfg.scope == "local" else np.arange(city.n_sectors)
    key = np.uint64(K.stream_key(cfg.seed, int(obs.t), agent))
    cands = candidate_controls(city, obs, agent)
    out = np.zeros((cands.size, cfg.samples), dtype=np.int64)
    for s in range(cfg.samples):
        reqs = sampled_requests(ctx, sectors, key, s)
        for c, u in enumerate(cands):
            sim = FleetSim(city, reqs, obs.pos)
            sim.state.t, sim.state.tau, sim.state.dest = obs.t, obs.tau.copy(), obs.dest.copy()
            home = ctx.home.astype(np.int64)
            joint = ctx.base_controls.copy()
            joint[:agent] = committed
            joint[agent] = u
            was_free = sim.observe().tau == 0
            g = total = sim.step(joint)
            home[was_free & (sim.observe().tau > 0)] = -1
            for _ in range(cfg.horizon):
                now = sim.observe()
                g = sim.step(homing_controls(city, now, home))
                home[(now.tau == 0) & (sim.observe().tau > 0)] = -1
                total += g
            out[c, s] = total + g
    return out


@pytest.mark.parametrize("ce,scope", [("limited", "local"), ("standard", "map"), ("counts", "local")])
def test_rebalance_base_costs_equal_the_simulator(ce: str, scope: str) -> None:
    city = grid_city(6, 5)
    fc = uniform_forecast(city, [0.3, 1.2, 0.1, 0.8])
    fc = type(fc)(eta=fc.eta, rho=fc.rho * (1 + np.arange(city.n_nodes) % 3), delta=fc.delta, beta=fc.beta)
    homed = 0
    for seed in range(4):
        # Few requests, so that the matching leaves taxis idle for the rebalancing to send.
        obs = random_state(city, np.random.default_rng(seed), taxis=9, requests=3)
        ctx = rebalance_context(city, obs, fc, horizon=5, samples=10, ce=ce, scope=scope, seed=seed)
        homed += int((ctx.home >= 0).sum())
        u = ctx.base_controls.copy()
        for agent in np.flatnonzero(obs.tau == 0):
            cands, costs = agent_costs(ctx, u[:agent], int(agent))
            np.testing.assert_array_equal(costs, reference_costs(ctx, u[:agent], int(agent)))
            u[agent] = plan_agent(ctx, u[:agent], int(agent))
    assert homed > 0, "no taxi was given a rebalancing target: the test checks nothing of it"


def test_the_decision_minute_plays_the_rebalance_policy() -> None:
    """The base controls of a minute are ``rebalance``'s joint control with the same forecast; targets only for idle taxis."""
    city = grid_city(6, 5)
    fc = uniform_forecast(city, [0.3, 1.2, 0.1, 0.8])
    obs = random_state(city, np.random.default_rng(3), taxis=9, requests=3)
    u, home = base_controls(city, RolloutConfig(base="rebalance"), obs, HourInputs.of(city, fc))
    want, want_home, m = rebalance_plan(city, obs, fc.eta, sector_anchors(city, fc.rho))
    np.testing.assert_array_equal(u, want)
    np.testing.assert_array_equal(home, want_home)
    assert np.all(home[obs.tau > 0] == -1) and np.all(home[m.taxis] == -1)
    idle = np.setdiff1d(np.flatnonzero(obs.tau == 0), m.taxis)
    assert np.all(home[idle] >= 0)


def test_rebalance_base_needs_the_hour_and_every_target() -> None:
    city = grid_city(4, 4)
    fc = uniform_forecast(city, [0.5, 0.5, 0.5, 0.5])
    obs = random_state(city, np.random.default_rng(0), taxis=4, requests=2)
    cfg = RolloutConfig(base="rebalance")
    tables = DemandTables.build(city, fc, cfg.ce, 0)
    with pytest.raises(ConfigError, match="needs the hour's forecast"):
        prepare_step(city, cfg, obs, tables, 5)
    with pytest.raises(ConfigError, match="every taxi's target"):
        prepare_step(city, cfg, obs, tables, 5, base=np.zeros(4, np.int32), home=np.zeros(2, np.int32))


def grid_episode(seed: int, requests: int):
    """A 12-minute episode of 9 taxis on a 6 × 6 grid: the city, its requests, the start and the context."""
    city = grid_city(6, 6)
    rng = np.random.default_rng(seed)
    reqs = Requests.sorted(rng.integers(0, 36, requests), rng.integers(0, 36, requests), rng.integers(0, 12, requests))
    start = rng.integers(0, 36, 9).astype(np.int32)
    return city, reqs, start, EpisodeContext(city=city, date=DATE, hour=19, minutes=12, seed=0, world=StubWorld(city, 12.0))


def test_surge_with_the_rebalance_base_is_deterministic_per_seed() -> None:
    city, reqs, start, ctx = grid_episode(11, 30)
    runs = [run_episode(city, make_policy("surge", city, forecast="true-rate", base="rebalance", horizon=4, samples=50, seed=5), reqs, start, ctx)
            for _ in range(2)]
    assert runs[0].decisions_sha256 == runs[1].decisions_sha256
    assert runs[0].total_cost == runs[1].total_cost


def test_surge_keeping_the_base_control_against_any_margin_is_rebalance() -> None:
    """With ``keep`` beyond any margin the samples can show, every decision is the base's: ``rebalance``'s, bit for bit."""
    city, reqs, start, ctx = grid_episode(4, 40)
    opts = dict(forecast="true-rate", base="rebalance", horizon=4, samples=40, seed=5)
    runs = {keep: run_episode(city, make_policy("surge", city, keep=keep, **opts), reqs, start, ctx) for keep in (None, 1e9)}
    plain = run_episode(city, make_policy("rebalance", city, forecast="true-rate"), reqs, start, ctx)
    assert runs[1e9].decisions_sha256 == plain.decisions_sha256
    assert runs[None].decisions_sha256 != plain.decisions_sha256, "the rollout never left the base: the test checks nothing"
