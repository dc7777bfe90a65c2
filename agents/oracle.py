"""Oracle: knows every future request and assigns taxis to them by auction.

Each minute it solves one assignment of taxis to the requests that have
entered or will enter within ``window`` minutes (the earliest ``3 × taxis``).
A busy taxi takes part from its drop-off point and the minute it frees up.
The benefit of a pairing is earlier pickup: ``T − max(arrival, entry)``, which
stands for the wait it saves against never being served.  Taxis then drive to
their request, wait for it if they are early, and pick it up.  Not achievable
in practice; it gives the lower bound that wait overhead is measured against.
"""

from __future__ import annotations

import numpy as np

from agents.auction import auction_assignment
from agents.base import EpisodeContext, Option, Policy, busy_next_hops, head_for, register
from city.errors import ConfigError
from city.graph import City
from city.sim import Observation, Requests


@register
class Oracle(Policy):
    name = "oracle"
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
        if context.future is None:
            raise ConfigError("oracle: the episode's future requests were not provided")
        self.future = context.future
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
