"""The two clairvoyant oracles: ``oracle`` (planned routes with chaining) and ``oracle-auction`` (the paper's).

Both know every request of the episode before it enters.  Neither is a
proven optimum: each is a heuristic with full information, so it measures
how far a policy is from what foresight achieves, and a policy that beats it
shows a weakness of the oracle, not a bound broken.

``oracle``
    Plans the whole episode once, at its first minute: one route per taxi
    (the requests it picks up, in order), timed with trip durations and
    chaining (a taxi serves a later request after its drop-off), built by
    best insertion and improved by large-neighbourhood search
    (:mod:`agents._oracle_kernels`).  The routes are then driven in a private
    copy of the simulator; where the simulator hands a taxi an older request
    waiting at the same intersection than the one planned, the two swap
    places in the plan.  It is *fortified*: it also runs ``oracle-auction``,
    ``ia`` and ``greedy`` on the same private copy and plays whichever of the
    four episodes costs least, so it is never worse than any of them on any
    instance.  The simulator is deterministic, so the episode it plays is the
    episode it measured.
``oracle-auction``
    The paper's oracle: each minute one assignment of taxis to the requests
    that have entered or will enter within ``window`` minutes (the earliest
    ``pool_factor × taxis``), solved by auction.  It ignores trip lengths and
    chaining; a busy taxi takes part from its drop-off point and the minute it
    frees up.
"""

from __future__ import annotations

import hashlib

import numpy as np

from agents import _oracle_kernels as OK
from agents.auction import auction_assignment
from agents.base import (
    EpisodeContext,
    Option,
    Policy,
    busy_next_hops,
    head_for,
    make_policy,
    register,
)
from city.errors import ConfigError
from city.graph import City
from city.sim import PICKUP, FleetSim, Observation, Requests

#: The policies a fortified ``oracle`` also runs, and plays if one of them costs less than its plan.
FORTIFY_WITH = ("oracle-auction", "ia", "greedy")


def _need_future(name: str, context: EpisodeContext) -> Requests:
    if context.future is None:
        raise ConfigError(f"{name}: the episode's future requests were not provided")
    return context.future


@register
class OracleAuction(Policy):
    """The paper's receding-horizon auction oracle (see the module docstring)."""

    name = "oracle-auction"
    clairvoyant = True
    options = (
        Option("window", int, low=0, high=1440, help="minutes ahead whose requests the auction assigns"),
        Option("pool_factor", int, low=1, high=100, help="requests in the auction per taxi (the earliest)"),
    )

    def __init__(self, city: City, window: int = 10, pool_factor: int = 3) -> None:
        super().__init__(city)
        self.window = int(window)
        self.pool_factor = int(pool_factor)
        self.future: Requests | None = None
        self.picked: np.ndarray | None = None

    def reset(self, context: EpisodeContext) -> None:
        self.future = _need_future(self.name, context)
        self.horizon = context.minutes + self.window + int(self.city.dist.max())
        self.picked = np.zeros(len(self.future), dtype=bool)

    def act(self, obs: Observation) -> np.ndarray:
        assert self.future is not None and self.picked is not None
        fut = self.future
        entered = int(np.searchsorted(fut.entry, obs.t, side="right"))
        self.picked[:entered] = True
        self.picked[obs.req_index] = False
        controls = busy_next_hops(self.city, obs)
        free = obs.tau == 0
        if not free.any():
            return controls
        upto = int(np.searchsorted(fut.entry, obs.t + self.window, side="right"))
        pool = np.flatnonzero(~self.picked[:upto])[: self.pool_factor * obs.pos.size]
        if pool.size == 0:
            return controls
        origin = np.where(free, obs.pos, obs.dest)
        ready = obs.t + obs.tau
        arrival = ready[:, None] + self.city.dist[origin[:, None], fut.pickup[pool][None, :]]
        pickup_time = np.maximum(arrival, fut.entry[pool][None, :])
        benefit = (self.horizon - pickup_time).astype(np.int64)
        if pool.size >= obs.pos.size:
            match = auction_assignment(benefit)
            taxis, reqs = np.arange(obs.pos.size), pool[match]
        else:
            match = auction_assignment(benefit.T)
            taxis, reqs = match, pool
        go = free[taxis]
        taxis, reqs = taxis[go], reqs[go]
        controls[taxis] = head_for(self.city, obs.pos[taxis], fut.pickup[reqs], fut.entry[reqs] <= obs.t)
        return controls


def plan_seed(context: EpisodeContext) -> int:
    """The planner's random seed, derived from the instance (date, hour, seed)."""
    text = f"oracle|{context.date.isoformat()}|{context.hour}|{context.seed}"
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:4], "little")


class _RouteDriver:
    """Drives planned routes minute by minute, mirroring the simulator's pickup rule to keep the plan consistent."""

    def __init__(self, city: City, requests: Requests, routes: list[list[int]]) -> None:
        self.city, self.req, self.routes = city, requests, [list(r) for r in routes]
        self.owner = np.full(len(requests), -1, dtype=np.int64)
        for m, route in enumerate(self.routes):
            self.owner[route] = m
        self.swaps = 0

    def controls(self, sim: FleetSim) -> np.ndarray:
        s, req = sim.state, self.req
        u = sim.busy_controls()
        waiting = set(sim.outstanding().tolist())
        for m in np.flatnonzero(s.tau == 0):
            route = self.routes[m]
            if not route:
                u[m] = s.pos[m]
                continue
            r = route[0]
            target = int(req.pickup[r])
            if s.pos[m] != target:
                u[m] = self.city.next_hop[s.pos[m], target]
            elif req.entry[r] > s.t:
                u[m] = s.pos[m]
            else:
                u[m] = PICKUP
                got = min(q for q in waiting if req.pickup[q] == target)  # the simulator's oldest-first rule
                waiting.discard(got)
                if got != r:
                    self._swap(m, r, got)
                route.pop(0)
        return u

    def _swap(self, m: int, planned: int, got: int) -> None:
        """Taxi ``m`` is handed ``got`` instead of ``planned``: whoever planned ``got`` takes ``planned``."""
        self.swaps += 1
        other = int(self.owner[got])
        if other >= 0:
            route = self.routes[other]
            route[route.index(got)] = planned
        self.owner[planned], self.owner[got] = other, m
        self.routes[m][0] = got


def drive(city: City, requests: Requests, start: np.ndarray, minutes: int, routes: list[list[int]]) -> tuple[int, np.ndarray, int]:
    """Total cost, joint controls and plan swaps of driving ``routes`` in the simulator."""
    sim = FleetSim(city, requests, start)
    driver = _RouteDriver(city, requests, routes)
    controls = np.zeros((minutes, len(start)), dtype=np.int32)
    cost = 0
    for t in range(minutes):
        controls[t] = driver.controls(sim)
        cost += sim.step(controls[t])
    return cost, controls, driver.swaps


def replay(city: City, policy: Policy, requests: Requests, start: np.ndarray, context: EpisodeContext) -> tuple[int, np.ndarray]:
    """Total cost and joint controls of ``policy`` on a private copy of the episode."""
    sim = FleetSim(city, requests, start)
    policy.reset(context)
    controls = np.zeros((context.minutes, len(start)), dtype=np.int32)
    cost = 0
    for t in range(context.minutes):
        controls[t] = policy.act(sim.observe())
        cost += sim.step(controls[t])
    return cost, controls


def plan(city: City, requests: Requests, start: np.ndarray, minutes: int, iters: int, seed: int) -> tuple[list[list[int]], int]:
    """Planned routes (request indices per taxi) and their value ``Σ_served (N - pickup step)``."""
    node_ptr, node_req = OK.node_queues(requests.pickup, city.n_nodes)
    routes, rlen, _pt, value = OK.plan_routes(
        city.dist, requests.pickup, requests.dropoff, requests.entry, np.asarray(start, dtype=np.int32), int(minutes), int(iters), int(seed),
        node_ptr, node_req,
    )
    return [routes[m, : rlen[m]].tolist() for m in range(len(start))], int(value)


@register
class Oracle(Policy):
    """Clairvoyant route planner with chaining, fortified by the simpler policies (see the module docstring).

    Parameters
    ----------
    city : City
    iters : int
        Large-neighbourhood-search iterations after the insertion start.
    fortify : int
        1 (default): play the cheapest of the plan and :data:`FORTIFY_WITH`;
        0: always play the plan (for measuring the planner itself).
    """

    name = "oracle"
    clairvoyant = True
    options = (
        Option("iters", int, low=0, high=10_000_000, help="large-neighbourhood-search iterations after the insertion start"),
        Option("fortify", int, low=0, high=1, help="1: play the cheapest of the plan and its fortifying policies; 0: the plan"),
    )

    def __init__(self, city: City, iters: int = 3000, fortify: int = 1) -> None:
        super().__init__(city)
        if iters < 0:
            raise ConfigError(f"policy 'oracle': iters must be non-negative, got {iters}")
        self.iters = int(iters)
        self.fortify = bool(fortify)
        self.context: EpisodeContext | None = None
        self.controls: np.ndarray | None = None
        self.chosen = ""
        self.costs: dict[str, int] = {}

    def reset(self, context: EpisodeContext) -> None:
        _need_future(self.name, context)
        self.context = context
        self.controls = None

    def act(self, obs: Observation) -> np.ndarray:
        ctx = self.context
        assert ctx is not None and ctx.future is not None, "reset() must be called before act()"
        if obs.t == 0:
            self._plan_episode(obs, ctx)
        if self.controls is None:
            raise ConfigError("oracle: the episode must be played from its first minute")
        return self.controls[obs.t].copy()

    def _plan_episode(self, obs: Observation, ctx: EpisodeContext) -> None:
        if not (obs.tau == 0).all():
            raise ConfigError("oracle: every taxi must be free at the first minute")
        req, start = ctx.future, obs.pos
        routes, _value = plan(self.city, req, start, ctx.minutes, self.iters, plan_seed(ctx))
        cost, controls, _swaps = drive(self.city, req, start, ctx.minutes, routes)
        self.costs = {"plan": cost}
        best = ("plan", cost, controls)
        if self.fortify:
            for name in FORTIFY_WITH:
                c, u = replay(self.city, make_policy(name, self.city), req, start, ctx)
                self.costs[name] = c
                if c < best[1]:
                    best = (name, c, u)
        self.chosen, self.controls = best[0], best[2]
