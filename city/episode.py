"""What an instance is and how an episode runs: requests, the fleet's start, and the loop of observe, act, step.

The runtime (one process per taxi) and the experiment harness both build
their instances here, so a distributed run and an in-process run of the same
(date, hour, seed) see the same requests and the same initial fleet.
"""

from __future__ import annotations

import datetime as dt
import time
from dataclasses import dataclass, replace
from typing import Any, ClassVar, Protocol

import numpy as np

from city.graph import City
from city.logs import steps
from city.sim import EpisodeResult, FleetSim, Observation, Requests


@dataclass(frozen=True)
class EpisodeContext:
    """What a policy is told when an episode starts.

    ``future`` (every request of the episode, including those not yet entered)
    is filled in only for clairvoyant policies such as the oracle.
    """

    city: City
    date: dt.date
    hour: int
    minutes: int
    seed: int
    world: Any = None
    future: Requests | None = None


class Controller(Protocol):
    """What :func:`run_episode` needs of a policy (``agents.base.Policy`` is one)."""

    clairvoyant: ClassVar[bool]

    def reset(self, context: EpisodeContext) -> None: ...

    def act(self, obs: Observation) -> np.ndarray: ...


def initial_positions(city: City, n_taxis: int, seed: int) -> np.ndarray:
    """A random placement of the fleet on pickup-eligible intersections (the paper's initial state)."""
    rng = np.random.default_rng(seed)
    return rng.choice(np.flatnonzero(city.pickup), size=n_taxis, replace=True).astype(np.int32)


def episode_requests(world: Any, date: dt.date, hour: int, minutes: int) -> Requests:
    """Requests for ``minutes`` minutes from ``hour``, spanning as many hours as needed."""
    parts = []
    for k in range((minutes + 59) // 60):
        when = dt.datetime.combine(date, dt.time()) + dt.timedelta(hours=hour + k)
        r = world.requests(when.date(), when.hour, min(60, minutes - 60 * k))
        parts.append((r.pickup, r.dropoff, r.entry + 60 * k))
    return Requests.sorted(*(np.concatenate(x) for x in zip(*parts)))


def run_episode(city: City, policy: Controller, requests: Requests, start: np.ndarray, context: EpisodeContext,
                show: str | None = None) -> EpisodeResult:
    """Run one policy for ``context.minutes`` steps and collect its metrics and controls.

    With ``show`` (what the run is), its minutes count as long work
    (:func:`city.logs.steps`): a bar where the application shows bars.
    """
    sim = FleetSim(city, requests, start)
    if policy.clairvoyant:
        context = replace(context, future=requests)
    policy.reset(context)
    costs: list[int] = []
    plan: list[float] = []
    cpu: list[float] = []
    controls = np.zeros((context.minutes, len(start)), dtype=np.int32)
    with steps(context.minutes if show else 0, "minute", show or "") as minutes:
        for t in range(context.minutes):
            obs = sim.observe()
            t0, c0 = time.perf_counter(), time.process_time()
            u = policy.act(obs)
            plan.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            controls[t] = u
            costs.append(sim.step(u))
            minutes.update()
    return sim.result(costs, controls, plan, cpu)
