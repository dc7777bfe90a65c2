"""``match``: optimal batched matching of free taxis to outstanding requests, every minute.

What fleet simulators and operators run as their dispatcher (Alonso-Mora et
al. 2017's batched assignment without pooling; AMoDeus's global bipartite
matching): each minute, the free taxis and the outstanding requests form a
bipartite graph, and a minimum-cost assignment
(``scipy.optimize.linear_sum_assignment``, exact) matches
``min(taxis, requests)`` pairs.  A matched taxi moves one hop toward its
request, or picks up when it stands on it; an unmatched free taxi stays.  The
matching is recomputed from scratch each minute, so a taxi may be re-matched
to a request that appeared closer.

Options
-------
cost : ``hops`` | ``sqrt`` | ``wait`` (default ``sqrt``)
    The cost of a pair. ``hops`` is the shortest-path distance from the taxi
    to the request's pickup (total pickup distance is minimised); ``sqrt``
    is its square root, a concave cost that prefers several mid-range pickups
    to one short and one very long one (what an overloaded fleet needs: many
    early pickups); ``wait`` is ``sqrt(hops) - wait_weight * minutes waited``,
    which prefers the requests that have waited longest.
wait_weight : float ≥ 0 (default 0.1)
    Hops of ``sqrt`` cost one minute of a request's waiting is worth, for ``cost=wait``.

``cost=sqrt`` had the least total cost of the three on validation data (a
July–August date only): ``benchmarks/practice-baselines/``.

A taxi standing on an outstanding request picks it up (the oldest there)
before the assignment, which then matches the other free taxis and
requests.  For ``hops`` and ``sqrt`` (``f(0) = 0`` least, ``f``
subadditive) some optimal assignment of all of them does so, so the rule
loses nothing and keeps ties from sending a taxi away from a waiting
passenger; for ``wait`` it is a rule: a passenger at the door is not left for
an older one elsewhere.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from agents.base import Option, Policy, busy_next_hops, register
from city.graph import City
from city.sim import PICKUP, Observation

COSTS = ("hops", "sqrt", "wait")


@dataclass(frozen=True)
class Matching:
    """One minute's matching: free taxis (fleet indices) and the observation columns of their requests."""

    taxis: np.ndarray
    requests: np.ndarray

    @property
    def size(self) -> int:
        return int(self.taxis.size)


def pair_costs(hops: np.ndarray, waited: np.ndarray, cost: str, wait_weight: float) -> np.ndarray:
    """The (taxis × requests) cost matrix of ``cost`` from pickup distances ``hops`` and minutes ``waited`` per request."""
    h = hops.astype(np.float64)
    if cost == "hops":
        return h
    c = np.sqrt(h)
    if cost == "wait":
        c = c - wait_weight * waited.astype(np.float64)[None, :]
    return c


def match_requests(city: City, obs: Observation, cost: str = "sqrt", wait_weight: float = 0.1) -> Matching:
    """The minimum-cost matching of ``obs``'s free taxis to its outstanding requests (see the module docstring)."""
    free = np.flatnonzero(obs.tau == 0)
    n_req = obs.req_pickup.size
    if free.size == 0 or n_req == 0:
        return Matching(np.empty(0, np.int64), np.empty(0, np.int64))
    taken = np.zeros(n_req, dtype=bool)
    on_spot_t, on_spot_r = [], []
    rest = []
    for taxi in free:  # taxis on a waiting request pick it up, oldest request first (as the simulator serves them)
        here = np.flatnonzero(~taken & (obs.req_pickup == obs.pos[taxi]))
        if here.size:
            taken[here[0]] = True
            on_spot_t.append(taxi)
            on_spot_r.append(here[0])
        else:
            rest.append(taxi)
    taxis, reqs = np.asarray(on_spot_t, np.int64), np.asarray(on_spot_r, np.int64)
    open_r = np.flatnonzero(~taken)
    if rest and open_r.size:
        rest_a = np.asarray(rest, np.int64)
        hops = city.dist[obs.pos[rest_a][:, None], obs.req_pickup[open_r][None, :]]
        c = pair_costs(hops, obs.t - obs.req_entry[open_r], cost, wait_weight)
        rows, cols = linear_sum_assignment(c)
        taxis = np.concatenate([taxis, rest_a[rows]])
        reqs = np.concatenate([reqs, open_r[cols]])
    return Matching(taxis, reqs)


def matched_controls(city: City, obs: Observation, m: Matching) -> np.ndarray:
    """Busy taxis' next hops, matched taxis one hop toward their request (pickup on it), everyone else staying."""
    u = busy_next_hops(city, obs)
    if m.size:
        pos, target = obs.pos[m.taxis], obs.req_pickup[m.requests]
        u[m.taxis] = np.where(pos == target, PICKUP, city.next_hop[pos, target])
    return u.astype(np.int32)


def match_options() -> tuple[Option, ...]:
    """The matching options, shared by ``match`` and ``rebalance``."""
    return (
        Option("cost", str, choices=COSTS, help="pair cost: pickup hops, their square root, or sqrt minus waiting (default sqrt)"),
        Option("wait_weight", float, low=0, help="for cost=wait: sqrt-hops one minute of waiting is worth (default 0.1)"),
    )


@register
class Match(Policy):
    """Optimal assignment of free taxis to outstanding requests every minute (see the module docstring)."""

    name = "match"
    central = True
    options = match_options()

    def __init__(self, city: City, cost: str = "sqrt", wait_weight: float = 0.1) -> None:
        super().__init__(city)
        self.cost, self.wait_weight = cost, float(wait_weight)
        self.last_matching: Matching | None = None

    def act(self, obs: Observation) -> np.ndarray:
        self.last_matching = match_requests(self.city, obs, self.cost, self.wait_weight)
        return matched_controls(self.city, obs, self.last_matching)
