"""The warm start: each policy begins an hour where its own previous hour left the fleet.

The paper's instances place the fleet uniformly at random, which flatters
rebalancing (it starts from an even spread) and fits no operating fleet.  In
the warm-start variant of the protocol the fleet of instance (date, hour,
seed) starts where the same policy, driving the hour before (same date and
demand world, 60 minutes, from the uniform start of the same seed), left it.
So every policy gets its own start, deterministic per seed.

Two choices make the end of the warm-up hour a start:

- a taxi still carrying a passenger at the end starts at that passenger's
  drop-off node, free (the simulator starts every taxi free; the trip's
  remaining minutes are not carried over);
- requests still waiting at the end belong to the previous hour and are
  dropped: the instance's requests are its own hour's, as in a cold start.

The oracles warm up the same way (clairvoyant over the warm-up hour), so the
wait overhead and the gap closed compare policies each from its own start.
"""

from __future__ import annotations

import datetime as dt
from typing import Any, Callable

import numpy as np

from city.episode import EpisodeContext, episode_requests, initial_positions, run_episode
from city.graph import City
from city.sim import FleetSim

#: Length of the warm-up hour, whatever the instance's episode length.
WARM_UP_MINUTES = 60


def warm_up_hour(date: dt.date, hour: int) -> tuple[dt.date, int]:
    """The date and hour before ``hour`` on ``date`` (hour 0 warms up at 23 h the day before)."""
    before = dt.datetime.combine(date, dt.time(hour)) - dt.timedelta(hours=1)
    return before.date(), before.hour


def end_positions(city: City, requests: Any, start: np.ndarray, controls: np.ndarray) -> np.ndarray:
    """Where the fleet is after replaying ``controls`` from ``start``: a busy taxi at its drop-off node."""
    sim = FleetSim(city, requests, start)
    for u in controls:
        sim.step(u)
    s = sim.state
    return np.where(s.tau > 0, s.dest, s.pos).astype(np.int32)


def warm_start_positions(city: City, world: Any, make: Callable[[dt.date, int], Any], date: dt.date, hour: int,
                         taxis: int, seed: int) -> np.ndarray:
    """The start of instance (``date``, ``hour``, ``seed``) for the policy that ``make(date, hour)`` builds.

    ``make`` gets the warm-up hour's date and hour, so that a rollout policy
    draws the random numbers of that hour's instance; ``world`` is the demand
    world of the warm-up hour's year.
    """
    wdate, whour = warm_up_hour(date, hour)
    requests = episode_requests(world, wdate, whour, WARM_UP_MINUTES)
    start = initial_positions(city, taxis, seed)
    context = EpisodeContext(city=city, date=wdate, hour=whour, minutes=WARM_UP_MINUTES, seed=seed, world=world)
    result = run_episode(city, make(wdate, whour), requests, start, context)
    return end_positions(city, requests, start, result.controls)
