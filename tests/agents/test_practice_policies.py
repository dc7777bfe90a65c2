"""``match`` and ``rebalance``: optimal against enumeration, rebalancing toward deficits, determinism, options, end to end."""

from __future__ import annotations

import datetime as dt
import itertools

import numpy as np
import pytest
from scipy.special import pdtrc

from agents.base import make_policy
from agents.match import COSTS, match_requests, matched_controls, pair_costs
from agents.rebalance import covered, rebalance_targets, sector_anchors, slot_values
from city.episode import EpisodeContext, episode_requests, initial_positions, run_episode
from city.graph import City
from city.sim import PICKUP, FleetSim, Observation
from coordinator.cli import main
from coordinator.experiments.evaluate import EvalConfig, evaluate
from tests.conftest import grid_edges, line_city


def grid_city(side: int) -> City:
    xy, u, v = grid_edges(side)
    return City.build("grid", xy, u, v, np.full(len(u), 100.0), np.zeros(side * side, dtype=np.int32), ["s0"])


def _obs(rng: np.random.Generator, n_nodes: int, taxis: int, requests: int, t: int = 20) -> Observation:
    pos = rng.integers(0, n_nodes, taxis).astype(np.int32)
    tau = np.where(rng.random(taxis) < 0.25, rng.integers(1, 5, taxis), 0).astype(np.int32)
    dest = np.where(tau > 0, rng.integers(0, n_nodes, taxis), -1).astype(np.int32)
    entry = np.sort(rng.integers(0, t + 1, requests)).astype(np.int32)
    return Observation(t=t, pos=pos, tau=tau, dest=dest, req_index=np.arange(requests), req_pickup=rng.integers(0, n_nodes, requests).astype(np.int32),
                       req_dropoff=rng.integers(0, n_nodes, requests).astype(np.int32), req_entry=entry)


def _enumerated_optimum(c: np.ndarray) -> float:
    """The least total cost over every matching of ``min(rows, cols)`` pairs, by enumeration."""
    if c.shape[0] <= c.shape[1]:
        return min(sum(c[i, j] for i, j in enumerate(cols)) for cols in itertools.permutations(range(c.shape[1]), c.shape[0]))
    return _enumerated_optimum(c.T)


@pytest.mark.parametrize("cost", COSTS)
def test_match_is_optimal_against_enumeration(cost: str) -> None:
    """Taxis on a waiting request pick it up; the rest are matched at least cost, checked by enumeration. For ``hops`` and
    ``sqrt`` the whole matching is optimal too (picking up on the spot loses nothing)."""
    city = grid_city(4)
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(60):
        obs = _obs(rng, city.n_nodes, int(rng.integers(1, 7)), int(rng.integers(1, 7)))
        free = np.flatnonzero(obs.tau == 0)
        m = match_requests(city, obs, cost, wait_weight=0.3)
        if free.size == 0:
            assert m.size == 0
            continue
        assert m.size == min(free.size, obs.req_pickup.size)
        assert len(set(m.taxis.tolist())) == m.size and len(set(m.requests.tolist())) == m.size
        spot = obs.pos[m.taxis] == obs.req_pickup[m.requests]
        rest_t = np.setdiff1d(free, m.taxis[spot])
        rest_r = np.setdiff1d(np.arange(obs.req_pickup.size), m.requests[spot])
        assert not np.isin(obs.pos[rest_t], obs.req_pickup[rest_r]).any()  # nobody left standing on a waiting request
        waited = obs.t - obs.req_entry
        for taxis, reqs in ((rest_t, rest_r), (free, np.arange(obs.req_pickup.size))):
            if cost == "wait" and taxis is free:
                continue
            c = pair_costs(city.dist[obs.pos[taxis][:, None], obs.req_pickup[reqs][None, :]], waited[reqs], cost, 0.3)
            row, col = {int(a): k for k, a in enumerate(taxis)}, {int(r): k for k, r in enumerate(reqs)}
            pairs = [(row[int(a)], col[int(r)]) for a, r in zip(m.taxis, m.requests) if int(a) in row]
            if taxis.size and reqs.size:
                assert sum(c[i, j] for i, j in pairs) == pytest.approx(_enumerated_optimum(c), abs=1e-9)
                checked += 1
    assert checked > 40


def test_match_controls_head_for_the_matched_request_and_leave_the_rest() -> None:
    city = grid_city(5)
    rng = np.random.default_rng(3)
    for _ in range(20):
        obs = _obs(rng, city.n_nodes, 8, 5)
        m = match_requests(city, obs)
        u = matched_controls(city, obs, m)
        busy = obs.tau > 0
        assert np.array_equal(u[busy], city.next_hop[obs.pos[busy], obs.dest[busy]])
        for a, r in zip(m.taxis, m.requests):
            target = obs.req_pickup[r]
            if obs.pos[a] == target:
                assert u[a] == PICKUP
            else:
                assert city.dist[u[a], target] == city.dist[obs.pos[a], target] - 1
        unmatched = np.setdiff1d(np.flatnonzero(~busy), m.taxis)
        assert np.array_equal(u[unmatched], obs.pos[unmatched])


def test_slots_send_idle_taxis_to_the_deficit_sector_only() -> None:
    city = line_city(12, sectors=3)  # sectors: nodes 0-3, 4-7, 8-11
    anchors = np.array([1, 5, 9])
    mu = np.array([0.0, 0.0, 6.0])  # demand expected in sector 2 only
    idle = np.array([0, 2, 4, 6], dtype=np.int32)
    sectors, worth = slot_values(mu, np.zeros(3, dtype=np.int64), idle.size, value=50.0)
    assert set(sectors.tolist()) == {2}
    assert np.all(np.diff(worth) < 0)  # each further taxi in the sector is worth less
    assert np.array_equal(rebalance_targets(city, idle, anchors, sectors, worth), [9, 9, 9, 9])
    # Sector 2 already covered by taxis about to be free there: no deficit, nobody moves.
    sectors, worth = slot_values(mu, np.array([0, 0, 40]), idle.size, value=50.0)
    assert np.array_equal(rebalance_targets(city, idle, anchors, sectors, worth), idle)
    # A low value moves only the taxis close enough for the slot to be worth the drive.
    sectors, worth = slot_values(mu, np.zeros(3, dtype=np.int64), idle.size, value=6.0)
    assert np.array_equal(rebalance_targets(city, idle, anchors, sectors, worth), [0, 2, 9, 9])


def test_anchors_sit_where_the_sector_demand_is() -> None:
    city = line_city(12, sectors=3)
    rho = np.zeros(12)
    rho[[3, 7, 8]] = 1.0
    assert np.array_equal(sector_anchors(city, rho), [3, 7, 8])


def _episode(scenario, policy: str, seed: int, minutes: int = 20, taxis: int = 30):
    date = dt.date(2022, 8, 2)
    req = episode_requests(scenario.world, date, 19, minutes)
    start = initial_positions(scenario.city, taxis, seed)
    ctx = EpisodeContext(city=scenario.city, date=date, hour=19, minutes=minutes, seed=seed, world=scenario.world)
    name, _, rest = policy.partition(":")
    opts = dict(kv.split("=") for kv in rest.split(",") if kv)
    return run_episode(scenario.city, make_policy(name, scenario.city, **opts), req, start, ctx), req, start, ctx


@pytest.fixture(scope="module")
def synthetic():
    from city.scenario import load_scenario

    return load_scenario("synthetic")


def test_rebalance_never_moves_a_matched_taxi_and_moves_idle_ones(synthetic) -> None:
    city, world = synthetic.city, synthetic.world
    date = dt.date(2022, 8, 2)
    req = episode_requests(world, date, 19, 30)
    sim = FleetSim(city, req, initial_positions(city, 60, 4))
    ctx = EpisodeContext(city=city, date=date, hour=19, minutes=30, seed=4, world=world)
    reb = make_policy("rebalance", city, forecast="true-rate")
    match = make_policy("match", city)
    reb.reset(ctx)
    moved = 0
    for _ in range(30):
        obs = sim.observe()
        u, v = reb.act(obs), match.act(obs)
        m = reb.last_matching
        keep = np.union1d(np.flatnonzero(obs.tau > 0), m.taxis)
        assert np.array_equal(u[keep], v[keep])  # busy and matched taxis: exactly match's controls
        idle = np.setdiff1d(np.flatnonzero(obs.tau == 0), m.taxis)
        if idle.size:
            fc, anchors = reb.hour_data(obs.t // 60)
            cover = covered(city, obs, m, reb.lookahead)
            for a, target in zip(idle, reb.last_targets):
                if target != obs.pos[a]:
                    moved += 1
                    s = int(city.node_sector[target])
                    assert u[a] == city.next_hop[obs.pos[a], target]
                    # the sector it drives to may still lack a taxi once those bound there are free: worth the drive
                    lacking = pdtrc(cover[s], fc.eta[s] * reb.lookahead)  # P(N_s ≥ cover_s + 1)
                    assert reb.value * lacking >= city.dist[obs.pos[a], target] > 0
        sim.step(u)
    assert moved > 0


@pytest.mark.parametrize("policy", ["match", "match:cost=wait", "rebalance", "rebalance:forecast=true-rate,lookahead=6"])
def test_deterministic_per_seed(synthetic, policy: str) -> None:
    a = _episode(synthetic, policy, seed=2)[0]
    b = _episode(synthetic, policy, seed=2)[0]
    c = _episode(synthetic, policy, seed=3)[0]
    assert a.decisions_sha256 == b.decisions_sha256 and a.total_cost == b.total_cost
    assert a.decisions_sha256 != c.decisions_sha256


@pytest.mark.parametrize(("label", "says"), [
    ("match:cost=euclid", "option cost='euclid' is not accepted; cost takes one of hops, sqrt, wait"),
    ("match:radius=3", "unknown option 'radius'; its options are cost, wait_weight"),
    ("rebalance:value=-1", "option value='-1' is not accepted; value takes a number of at least 0"),
    ("rebalance:lookahead=0", "lookahead takes an integer from 1 to 60"),
    ("rebalance:forecast=oracle", "forecast takes one of model, previous-hour, true-rate"),
])
def test_bad_options_are_one_line(label: str, says: str, capsys) -> None:
    assert main(["evaluate", "--hours", "19", "--seeds", "1", "--taxis", "4", "--minutes", "2", "--policies", label]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0], err


def test_forecast_flag_reaches_every_policy_that_reads_one() -> None:
    import argparse

    from coordinator.cli.options import rollout_options

    ns = argparse.Namespace(horizon=None, samples=None, forecast="true-rate", model=None)
    got = rollout_options(ns, ["surge", "rebalance", "rebalance:value=5", "garces2023", "match", "greedy"])
    assert got == {"surge": {"forecast": "true-rate"}, "rebalance": {"forecast": "true-rate"},
                   "rebalance:value=5": {"forecast": "true-rate"}}


def test_both_run_in_evaluate_end_to_end() -> None:
    cfg = EvalConfig(hours=[19], seeds=2, taxis=8, minutes=6, policies=["greedy", "match", "rebalance", "rebalance:forecast=true-rate"],
                     policy_options={"oracle": {"iters": 20}, "rebalance": {"forecast": "previous-hour"}})
    doc = evaluate(cfg, progress=lambda _m: None)
    rows = {(e["policy"], e["seed"]): e for e in doc["episodes"]}
    assert len(rows) == 8
    for (policy, seed), e in rows.items():
        assert e["served"] > 0 and e["plan_seconds_per_step"] < 0.05, (policy, seed)
        assert e["total_cost"] >= 0 and len(e["decisions_sha256"]) == 64
