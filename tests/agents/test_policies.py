"""Baselines, the registry, and the auction against the Hungarian algorithm."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from agents.auction import auction_assignment
from agents.base import EpisodeContext, make_policy, policy_names
from agents.ia import ble_match
from city.episode import run_episode
from city.errors import ConfigError
from city.sim import PICKUP, FleetSim, Requests
from tests.conftest import line_city


@pytest.mark.parametrize("shape", [(1, 1), (3, 3), (5, 8), (12, 12), (20, 35), (40, 60)])
def test_auction_matches_hungarian(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    for _ in range(5):
        benefit = rng.integers(0, 1000, size=shape)
        a = auction_assignment(benefit)
        assert len(set(a.tolist())) == shape[0]
        rows, cols = linear_sum_assignment(benefit, maximize=True)
        assert benefit[np.arange(shape[0]), a].sum() == benefit[rows, cols].sum()


def test_auction_with_ties_and_negative_benefits() -> None:
    benefit = np.array([[5, 5, 5], [5, 5, 5], [-3, -3, 7]])
    a = auction_assignment(benefit)
    rows, cols = linear_sum_assignment(benefit, maximize=True)
    assert benefit[np.arange(3), a].sum() == benefit[rows, cols].sum()


def test_auction_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="transpose"):
        auction_assignment(np.zeros((3, 2), dtype=int))
    with pytest.raises(ValueError, match="integers"):
        auction_assignment(np.zeros((2, 2)))


def test_ble_match_takes_closest_pairs_first() -> None:
    d = np.array([[1, 5], [2, 9]])
    rows, cols = ble_match(d)
    assert list(zip(rows.tolist(), cols.tolist())) == [(0, 0), (1, 1)]


def test_unknown_policy_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="unknown policy 'nope'"):
        make_policy("nope", line_city(3))
    assert {"greedy", "ia", "oracle", "oracle-auction"} <= set(policy_names())


def _context(city, minutes: int) -> EpisodeContext:
    return EpisodeContext(city=city, date=dt.date(2022, 11, 17), hour=19, minutes=minutes, seed=0)


def test_greedy_heads_for_nearest_and_picks_up() -> None:
    city = line_city(7)
    r = Requests.sorted(np.array([5, 1]), np.array([6, 0]), np.array([0, 0]))
    sim = FleetSim(city, r, np.array([3, 0]))
    u = make_policy("greedy", city).act(sim.observe())
    assert u.tolist() == [4, 1]  # taxi 0: nodes 5 and 1 both 2 hops away, the older request wins
    sim.step(u)
    u = make_policy("greedy", city).act(sim.observe())
    assert u.tolist() == [5, PICKUP]


def test_ia_does_not_send_two_taxis_to_one_request() -> None:
    city = line_city(7)
    r = Requests.sorted(np.array([3, 6]), np.array([0, 0]), np.array([0, 0]))
    sim = FleetSim(city, r, np.array([2, 4]))
    greedy = make_policy("greedy", city).act(sim.observe())
    ia = make_policy("ia", city).act(sim.observe())
    assert greedy.tolist() == [3, 3]
    assert ia.tolist() == [3, 5]


@pytest.mark.parametrize("oracle", ["oracle", "oracle-auction"])
def test_oracles_preposition_for_future_requests(oracle: str) -> None:
    city = line_city(9)
    r = Requests.sorted(np.array([8]), np.array([0]), np.array([4]))
    res = {}
    for name in ("greedy", oracle):
        res[name] = run_episode(city, make_policy(name, city), r, np.array([0]), _context(city, 12))
    assert res[oracle].total_cost == 4  # drives 8 hops, request waits from minute 4 to 8
    assert res["greedy"].total_cost == 8  # starts driving at minute 4 and is still on its way at the end
    assert res["greedy"].served == 0


@pytest.mark.parametrize("oracle", ["oracle", "oracle-auction"])
def test_oracles_require_future(oracle: str) -> None:
    city = line_city(3)
    with pytest.raises(ConfigError, match="future"):
        make_policy(oracle, city).reset(_context(city, 5))


def test_option_strings_are_parsed_to_their_declared_types() -> None:
    from agents.base import parse_policy

    assert parse_policy("surge:horizon=5,samples=20,prune=none,scope=map") == (
        "surge", {"horizon": 5, "samples": 20, "prune": None, "scope": "map"})
    assert parse_policy("garces2023:prune=auto,seed=3")[1] == {"prune": "auto", "seed": 3}
    assert parse_policy("oracle-auction:window=0")[1] == {"window": 0}


def test_surge_plans_over_rebalance_by_default_and_as_the_paper_with_its_options_pinned() -> None:
    from agents.base import parse_policy, policy_class
    from agents.rollout_config import RolloutConfig, default_prune
    from agents.rollout_policy import EXACT, PAPER, pinned_options

    surge, garces = policy_class("surge"), policy_class("garces2023")
    c = surge.rollout_config()
    assert (c.base, c.scope, c.horizon, c.samples, c.adaptive, c.batch, c.cap, c.keep) == ("rebalance", "map", 20, 200, 1.0, 50, 12, 2.0)
    assert c.prune == default_prune(20)
    paper = RolloutConfig(prune=default_prune(10))  # the dataclass's own defaults are the paper's
    assert surge.rollout_config(**PAPER) == paper
    assert surge.rollout_config(**parse_policy("surge:base=greedy,scope=local,horizon=10,samples=1000,adaptive=none,cap=none,batch=100,keep=none")[1]) == paper
    off = surge.rollout_config(cap=None)  # each approximation is turned off on its own
    assert (off.adaptive, off.batch, off.cap) == (1.0, 50, None)
    assert garces.rollout_config() == garces.rollout_config(**EXACT)
    # Pinned: what the label does not set and today's default differs in.
    assert pinned_options("surge:cap=12,forecast=true-rate") == {"horizon": 10, "samples": 1000, "base": "greedy", "scope": "local",
                                                                  "adaptive": None, "batch": 100, "keep": None}
    fast = "surge:base=rebalance,scope=map,horizon=20,samples=200,cap=12,adaptive=1"
    assert pinned_options(fast, {**PAPER, "batch": 50}) == {"keep": None}  # planned when surge took its best candidate
    assert pinned_options(f"{fast},keep=2", {**PAPER, "batch": 50}) == {}
    assert pinned_options("garces2023") == pinned_options("greedy") == {}


def test_every_policy_declares_exactly_the_options_its_constructor_takes() -> None:
    import inspect

    from agents.base import policy_class
    from agents.rollout_policy import RolloutPolicy

    for name in policy_names():
        cls = policy_class(name)
        params = [p for p in inspect.signature(cls.__init__).parameters.values()
                  if p.name not in ("self", "city") and p.kind is not p.VAR_KEYWORD]
        if issubclass(cls, RolloutPolicy):
            params += list(inspect.signature(cls.rollout_config).parameters.values())
        assert sorted(o.name for o in cls.options) == sorted(p.name for p in params), name


@pytest.mark.parametrize(("name", "options", "message"), [
    ("surge", {"horizon": 0}, "option horizon=0 is not accepted; horizon takes an integer from 1 to 240"),
    ("surge", {"samples": 2.5}, "option samples=2.5 is not accepted"),
    ("ia", {"x": 1}, "policy 'ia': unknown option 'x'; it takes no options"),
])
def test_make_policy_checks_typed_options(name: str, options: dict, message: str) -> None:
    city = line_city(4)
    with pytest.raises(ConfigError, match=message.replace("(", r"\(")):
        make_policy(name, city, **options)
