"""The fleet world of the paper (§3): state, controls, transition and stage cost.

A step is one minute.  Free taxis move to an out-neighbour, stay, or pick up
(``PICKUP``) the oldest outstanding request waiting at their intersection.  A
taxi that picks up is busy for ``τ = max(1, hops(ρ, δ))`` steps, follows the
shortest path one hop per step and is free again at δ.  Controls are applied in
agent order, so when two taxis pick up at one intersection the earlier agent
gets the oldest request and the later one the next, or stays if none is left.
The stage cost after step ``t`` is the number of requests that have entered
(entry minute ≤ t) and are still waiting.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from city.graph import City

#: Control code for "pick up a request here"; any other control is a node id.
PICKUP = -1


@dataclass(frozen=True)
class Requests:
    """All requests of an episode, sorted by entry minute (then by index)."""

    pickup: np.ndarray
    dropoff: np.ndarray
    entry: np.ndarray

    def __post_init__(self) -> None:
        for name in ("pickup", "dropoff", "entry"):
            object.__setattr__(self, name, np.ascontiguousarray(getattr(self, name), dtype=np.int32))
        if not (len(self.pickup) == len(self.dropoff) == len(self.entry)):
            raise ValueError("requests: pickup, dropoff and entry must have the same length")
        if len(self.entry) > 1 and np.any(np.diff(self.entry) < 0):
            raise ValueError("requests: entry minutes must be sorted")

    def __len__(self) -> int:
        return int(self.entry.shape[0])

    @staticmethod
    def sorted(pickup: np.ndarray, dropoff: np.ndarray, entry: np.ndarray) -> "Requests":
        order = np.argsort(np.asarray(entry), kind="stable")
        return Requests(np.asarray(pickup)[order], np.asarray(dropoff)[order], np.asarray(entry)[order])


@dataclass
class FleetState:
    """x_t = <ν_t, τ_t, outstanding requests> plus bookkeeping for metrics."""

    t: int
    pos: np.ndarray
    tau: np.ndarray
    dest: np.ndarray
    picked_at: np.ndarray

    @property
    def free(self) -> np.ndarray:
        return self.tau == 0


@dataclass(frozen=True)
class Observation:
    """What a non-clairvoyant policy sees at minute ``t``: the fleet and the outstanding requests."""

    t: int
    pos: np.ndarray
    tau: np.ndarray
    dest: np.ndarray
    req_index: np.ndarray
    req_pickup: np.ndarray
    req_dropoff: np.ndarray
    req_entry: np.ndarray

    @property
    def free(self) -> np.ndarray:
        return self.tau == 0


@dataclass
class EpisodeResult:
    total_cost: int
    outstanding_end: int
    served: int
    n_requests: int
    stage_costs: list[int]
    controls: np.ndarray
    plan_seconds: list[float] = field(default_factory=list)
    plan_cpu_seconds: list[float] = field(default_factory=list)

    @property
    def decisions_sha256(self) -> str:
        return decisions_hash(self.controls)


def decisions_hash(controls: np.ndarray) -> str:
    """SHA-256 of the joint controls of every step, as little-endian int32."""
    return hashlib.sha256(np.ascontiguousarray(controls, dtype="<i4").tobytes()).hexdigest()


class FleetSim:
    """Ground-truth simulator for one episode.

    Parameters
    ----------
    city : City
    requests : Requests
        Every request of the episode, including those not yet entered.
    start_pos : ndarray
        Initial intersection of each taxi; all taxis start free.
    """

    def __init__(self, city: City, requests: Requests, start_pos: np.ndarray) -> None:
        self.city = city
        self.requests = requests
        m = len(start_pos)
        self.state = FleetState(
            t=0,
            pos=np.asarray(start_pos, dtype=np.int32).copy(),
            tau=np.zeros(m, dtype=np.int32),
            dest=np.full(m, -1, dtype=np.int32),
            picked_at=np.full(len(requests), -1, dtype=np.int32),
        )

    @property
    def n_taxis(self) -> int:
        return int(self.state.pos.shape[0])

    def outstanding(self) -> np.ndarray:
        """Indices of requests entered by now and not picked, oldest first."""
        entered = int(np.searchsorted(self.requests.entry, self.state.t, side="right"))
        return np.flatnonzero(self.state.picked_at[:entered] < 0)

    def observe(self) -> Observation:
        idx = self.outstanding()
        s = self.state
        return Observation(
            t=s.t,
            pos=s.pos.copy(),
            tau=s.tau.copy(),
            dest=s.dest.copy(),
            req_index=idx,
            req_pickup=self.requests.pickup[idx],
            req_dropoff=self.requests.dropoff[idx],
            req_entry=self.requests.entry[idx],
        )

    def busy_controls(self) -> np.ndarray:
        """ζ: the next hop of every busy taxi (entries of free taxis are meaningless)."""
        s = self.state
        return self.city.next_hop[s.pos, np.maximum(s.dest, 0)].astype(np.int32)

    def step(self, controls: np.ndarray) -> int:
        """Apply one joint control in agent order and return the stage cost g_t."""
        s = self.state
        controls = np.asarray(controls, dtype=np.int32)
        if controls.shape != s.pos.shape:
            raise ValueError(f"controls: expected {s.pos.shape[0]} entries, got {controls.shape}")
        busy = s.tau > 0
        if busy.any():
            expected = self.busy_controls()[busy]
            bad = np.flatnonzero(controls[busy] != expected)
            if bad.size:
                taxi = int(np.flatnonzero(busy)[bad[0]])
                raise ValueError(f"controls[{taxi}]: busy taxi must take next hop {int(expected[bad[0]])}, got {int(controls[taxi])}")
        self._check_moves(controls, ~busy)

        entered = int(np.searchsorted(self.requests.entry, s.t, side="right"))
        waiting = s.picked_at[:entered] < 0
        pick_nodes = self.requests.pickup[:entered]
        new_pos = np.where(busy, controls, s.pos)
        new_tau = np.where(busy, s.tau - 1, 0)
        new_dest = s.dest.copy()
        free_moves = ~busy & (controls != PICKUP)
        new_pos[free_moves] = controls[free_moves]
        for taxi in np.flatnonzero(~busy & (controls == PICKUP)):
            here = np.flatnonzero(waiting & (pick_nodes == s.pos[taxi]))
            if here.size == 0:
                continue
            r = int(here[0])
            waiting[r] = False
            s.picked_at[r] = s.t
            drop = int(self.requests.dropoff[r])
            new_tau[taxi] = max(1, int(self.city.dist[s.pos[taxi], drop]))
            new_dest[taxi] = drop
        new_dest[(busy & (new_tau == 0))] = -1
        s.pos, s.tau, s.dest = new_pos.astype(np.int32), new_tau.astype(np.int32), new_dest
        cost = int(waiting.sum())
        s.t += 1
        return cost

    def _check_moves(self, controls: np.ndarray, free: np.ndarray) -> None:
        idx = np.flatnonzero(free & (controls != PICKUP))
        if idx.size == 0:
            return
        src, dst = self.state.pos[idx], controls[idx]
        ok = (dst == src) | ((dst >= 0) & (dst < self.city.n_nodes) & (self.city.dist[src, np.clip(dst, 0, None)] == 1))
        if not ok.all():
            taxi = int(idx[np.flatnonzero(~ok)[0]])
            raise ValueError(
                f"controls[{taxi}]: {int(controls[taxi])} is not a neighbour of intersection {int(self.state.pos[taxi])}"
            )

    def result(self, stage_costs: list[int], controls: np.ndarray, plan_seconds: list[float],
               plan_cpu_seconds: list[float] | None = None) -> EpisodeResult:
        served = int((self.state.picked_at >= 0).sum())
        return EpisodeResult(
            total_cost=int(sum(stage_costs)),
            outstanding_end=stage_costs[-1] if stage_costs else 0,
            served=served,
            n_requests=len(self.requests),
            stage_costs=stage_costs,
            controls=controls,
            plan_seconds=plan_seconds,
            plan_cpu_seconds=plan_cpu_seconds or [],
        )
