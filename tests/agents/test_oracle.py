"""The route-planning oracle: exact timing, never worse than the auction, and optimal on tiny instances.

The optimum is found by exhaustive search over every joint control sequence
(memoised on the simulator's state), so it is the true minimum total cost of
the instance, not the optimum of the planner's route model.
"""

from __future__ import annotations

import datetime as dt
from functools import lru_cache

import numpy as np
import pytest

from agents import oracle as O
from agents.base import EpisodeContext, make_policy
from city.episode import episode_requests, initial_positions, run_episode
from city.graph import City
from city.sim import PICKUP, Requests
from tests.conftest import grid_edges


def grid_city(side: int) -> City:
    xy, u, v = grid_edges(side)
    return City.build("grid", xy, u, v, np.full(len(u), 100.0), np.zeros(side * side, dtype=np.int32), ["all"])


def optimum(city: City, req: Requests, start: np.ndarray, minutes: int) -> int:
    """Least total cost over all joint control sequences, by memoised exhaustive search on the simulator's rules."""
    pick, drop, entry = req.pickup.tolist(), req.dropoff.tolist(), req.entry.tolist()
    nbrs = [[i, *city.neighbors(i)] for i in range(city.n_nodes)]
    R = len(pick)

    @lru_cache(maxsize=None)
    def best(t: int, pos: tuple, tau: tuple, dest: tuple, picked: int) -> int:
        if t == minutes:
            return 0
        options = []
        for m in range(len(pos)):
            if tau[m] > 0:
                options.append([int(city.next_hop[pos[m], dest[m]])])
            else:
                here = any(not picked >> r & 1 and entry[r] <= t and pick[r] == pos[m] for r in range(R))
                options.append(nbrs[pos[m]] + ([PICKUP] if here else []))
        out = None
        for joint in _product(options):
            p, ta, de, pk = list(pos), list(tau), list(dest), picked
            for m, u in enumerate(joint):
                if tau[m] > 0:
                    p[m], ta[m] = u, tau[m] - 1
                    de[m] = dest[m] if ta[m] > 0 else -1
                elif u == PICKUP:
                    r = next((r for r in range(R) if not pk >> r & 1 and entry[r] <= t and pick[r] == pos[m]), None)
                    if r is None:  # an earlier taxi took the last request here: this one stays
                        continue
                    pk |= 1 << r
                    ta[m], de[m] = max(1, int(city.dist[pick[r], drop[r]])), drop[r]
                else:
                    p[m] = u
            cost = sum(1 for r in range(R) if entry[r] <= t and not pk >> r & 1)
            total = cost + best(t + 1, tuple(p), tuple(ta), tuple(de), pk)
            out = total if out is None else min(out, total)
        return out

    return best(0, tuple(int(x) for x in start), (0,) * len(start), (-1,) * len(start), 0)


def _product(options: list[list[int]]):
    if not options:
        yield ()
        return
    for u in options[0]:
        for rest in _product(options[1:]):
            yield (u, *rest)


def _context(city: City, minutes: int, seed: int = 0) -> EpisodeContext:
    return EpisodeContext(city=city, date=dt.date(2022, 11, 17), hour=19, minutes=minutes, seed=seed)


def _tiny(seed: int) -> tuple[City, Requests, np.ndarray, int]:
    rng = np.random.default_rng(seed)
    city = grid_city(3)
    n_req, minutes = 5, 9
    req = Requests.sorted(rng.integers(0, 9, n_req), rng.integers(0, 9, n_req), rng.integers(0, 5, n_req))
    return city, req, rng.integers(0, 9, 2).astype(np.int32), minutes


def test_planned_routes_are_driven_exactly_as_timed(synthetic_scenario) -> None:  # noqa: ANN001
    city, world = synthetic_scenario.city, synthetic_scenario.world
    req = episode_requests(world, dt.date(2022, 11, 17), 19, 30)
    start = initial_positions(city, 30, 4)
    routes, value = O.plan(city, req, start, 30, 200, 7)
    cost, _controls, swaps = O.drive(city, req, start, 30, routes)
    assert swaps == 0  # the plan was projected onto the simulator's oldest-first pickups
    assert cost == int((30 - req.entry).sum()) - value
    again = O.plan(city, req, start, 30, 200, 7)
    assert again == (routes, value)


def test_oracle_is_no_worse_than_the_auction(synthetic_scenario) -> None:  # noqa: ANN001
    city, world = synthetic_scenario.city, synthetic_scenario.world
    for hour, seed in ((17, 0), (19, 1), (21, 2)):
        req = episode_requests(world, dt.date(2022, 11, 17), hour, 30)
        start = initial_positions(city, 25, seed)
        ctx = _context(city, 30, seed)
        res = {name: run_episode(city, make_policy(name, city, **opts), req, start, ctx)
               for name, opts in (("oracle", {"iters": 300}), ("oracle-auction", {}))}
        assert res["oracle"].total_cost <= res["oracle-auction"].total_cost
        plan_only = run_episode(city, make_policy("oracle", city, iters=300, fortify=0), req, start, ctx)
        assert plan_only.total_cost <= res["oracle-auction"].total_cost, (hour, seed)  # the planner itself, unfortified


def test_oracle_reaches_the_optimum_of_tiny_instances() -> None:
    reached = 0
    for seed in range(10):
        city, req, start, minutes = _tiny(seed)
        best = optimum(city, req, start, minutes)
        ctx = _context(city, minutes, seed)
        got = run_episode(city, make_policy("oracle", city, iters=200), req, start, ctx).total_cost
        auction = run_episode(city, make_policy("oracle-auction", city), req, start, ctx).total_cost
        assert best <= got <= auction
        reached += got == best
    assert reached >= 8


@pytest.mark.parametrize("bad", [{"iters": -1}])
def test_oracle_rejects_bad_options(bad: dict) -> None:
    from city.errors import ConfigError

    with pytest.raises(ConfigError, match="iters"):
        make_policy("oracle", grid_city(2), **bad)
