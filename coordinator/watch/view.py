"""The fleet as the page shows it: one frame per moment, built the same way live and in replay.

A frame holds the minute, every taxi's node and state, the waiting
requests with their age, both demand layers by sector and the side panel's
counts.  The states:

* ``free``: no passenger and no pickup under way;
* ``to pickup``: free, with a committed control that picks up here (-1) or
  moves one hop closer to the nearest waiting request;
* ``occupied``: carrying a passenger (``tau > 0``);
* ``deciding``: its turn for the minute is out and its control not yet
  committed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from city.graph import City

FREE, TO_PICKUP, OCCUPIED, DECIDING = 0, 1, 2, 3
STATES = ("free", "to pickup", "occupied", "deciding")
#: Minutes of entries the realised demand layer averages over.
REALISED_WINDOW = 60


@dataclass
class Minute:
    """What is known of one minute: the fleet at its start and the turns and commitments of its decisions."""

    t: int
    pos: np.ndarray
    tau: np.ndarray
    turns: set[int] = field(default_factory=set)
    committed: dict[int, int] = field(default_factory=dict)
    #: The dependency wave of each agent whose turn went out (0 = the first).
    wave_of: dict[int, int] = field(default_factory=dict)

    @property
    def waves(self) -> int:
        return max(self.wave_of.values(), default=-1) + 1


class FleetView:
    """Accumulates the run minute by minute and renders frames; the caller feeds it states, turns and commitments."""

    def __init__(self, city: City, taxis: int, minutes: int) -> None:
        self.city = city
        self.taxis = taxis
        self.minutes = minutes
        #: Outstanding requests: id -> (pickup node, entry minute).
        self.requests: dict[int, tuple[int, int]] = {}
        #: Requests that entered each minute, by sector.
        self.entered = np.zeros((minutes + 1, city.n_sectors), dtype=np.int32)
        #: Forecast η (requests a minute) by episode hour, once known.
        self.eta: dict[int, np.ndarray] = {}
        self.now: Minute | None = None
        self.cost = 0
        #: The minutes (1-based, inclusive) whose stage costs ``cost`` sums: a minute's cost shows in the next state.
        self.cost_to = 0
        self.served = 0
        self.fallbacks = 0
        #: The first minute this view saw from its start (a watcher that joins late counts from there).
        self.since: int | None = None
        self.done = False
        self.stop_reason: str | None = None
        self._seen: set[int] = set()
        #: Turns and commitments of minutes whose state has not come yet (zenoh keeps no order across keys).
        self.early: dict[int, Minute] = {}

    # ------------------------------------------------------------ input
    def state(self, t: int, full: bool, pos: np.ndarray, tau: np.ndarray, new: tuple[np.ndarray, np.ndarray, np.ndarray],
              picked: np.ndarray, outstanding: int) -> bool:
        """Apply minute ``t``'s state; ``False`` when a delta does not follow (the caller asks for a snapshot)."""
        index, pickup, entry = (np.asarray(a) for a in new)
        if not full and (self.now is None or t != self.now.t + 1):
            return False
        if full:
            self.requests.clear()
            if self.since is None:
                self.since = t
        for r in np.asarray(picked).tolist():
            self.requests.pop(r, None)
        sectors = self.city.node_sector[pickup] if len(pickup) else np.zeros(0, dtype=np.int64)
        for r, p, e, s in zip(index.tolist(), pickup.tolist(), entry.tolist(), sectors.tolist()):
            if r not in self._seen and 0 <= e <= self.minutes:
                self._seen.add(r)
                self.entered[e, s] += 1
            self.requests[r] = (p, e)
        if len(self.requests) != outstanding:
            return False
        if not full:  # minute t-1's stage cost: requests entered by t-1 still waiting at t; and its pickups
            self.cost += outstanding - int(np.count_nonzero(entry == t))
            self.cost_to = t
            self.served += len(picked)
        early = self.early.pop(t, None)
        self.now = Minute(t=t, pos=np.asarray(pos, dtype=np.int64), tau=np.asarray(tau, dtype=np.int64))
        if early is not None:
            self.now.turns, self.now.committed, self.now.wave_of = early.turns, early.committed, early.wave_of
        for m in [m for m in self.early if m < t]:
            del self.early[m]
        return True

    def _minute(self, t: int) -> Minute | None:
        """Where minute ``t``'s decisions go: the current minute, one still to come, or nowhere (a past one)."""
        if self.now is not None and self.now.t == t:
            return self.now
        if self.now is None or t > self.now.t:
            return self.early.setdefault(t, Minute(t=t, pos=np.zeros(0, np.int64), tau=np.zeros(0, np.int64)))
        return None

    def wave_after(self, t: int, deps: list[int]) -> int:
        """The wave of a turn of minute ``t`` that depends on ``deps``: one after the latest of theirs."""
        m = self._minute(t)
        known = m.wave_of if m is not None else {}
        return 1 + max((known.get(d, 0) for d in deps), default=-1)

    def turn(self, t: int, agent: int, wave: int) -> None:
        """A turn went out: the agent is deciding."""
        m = self._minute(t)
        if m is not None:
            m.turns.add(agent)
            m.wave_of[agent] = wave

    def commit(self, t: int, agent: int, control: int, by: str) -> None:
        """A control was committed (``by = "base"``: a fallback for a silent taxi)."""
        m = self._minute(t)
        if m is None:
            return
        if agent not in m.committed and by == "base":
            self.fallbacks += 1
        m.committed[agent] = control

    def forecast(self, hour: int, sector: int, eta: float) -> None:
        self.eta.setdefault(hour, np.full(self.city.n_sectors, np.nan))[sector] = eta

    def stop(self, t: int, reason: str, cost: int | None = None, served: int | None = None) -> None:
        """The run ended; a replay knows the last minute's cost and service, which no later state reports live."""
        self.done, self.stop_reason = True, reason
        if cost is not None:
            self.cost, self.cost_to = cost, t
        if served is not None:
            self.served = served

    # ------------------------------------------------------------ output
    def states(self) -> np.ndarray:
        """Each taxi's state code (:data:`STATES`)."""
        now = self.now
        assert now is not None
        out = np.full(self.taxis, FREE, dtype=np.int64)
        out[now.tau > 0] = OCCUPIED
        waiting = np.array(sorted({p for p, _ in self.requests.values()}), dtype=np.int64)
        for a in np.flatnonzero(now.tau == 0).tolist():
            c = now.committed.get(a)
            if c is None:
                out[a] = DECIDING if a in now.turns and not self.done else FREE
            elif c < 0 or (waiting.size and self.city.dist[c, waiting].min() < self.city.dist[now.pos[a], waiting].min()):
                out[a] = TO_PICKUP
        return out

    def frame(self) -> dict:
        """The page's picture of this moment, JSON-ready."""
        now = self.now
        if now is None:
            return {"minute": 0, "minutes": self.minutes, "taxis": self.taxis, "waiting_for": "the run's first state"}
        hour = now.t // 60
        lo = max(0, now.t + 1 - REALISED_WINDOW)
        realised = self.entered[lo:now.t + 1].sum(axis=0) / (now.t + 1 - lo)
        eta = self.eta.get(hour)
        ages = sorted(((p, now.t - e) for p, e in self.requests.values()), key=lambda x: -x[1])
        return {
            "minute": min(now.t + 1, self.minutes) if not self.done else self.minutes,
            "minutes": self.minutes,
            "t": now.t,
            "hour": hour,
            "taxis": self.taxis,
            "pos": now.pos.tolist(),
            "state": self.states().tolist(),
            "requests": [x for pair in ages for x in pair],
            "forecast": None if eta is None else [None if np.isnan(v) else round(float(v), 4) for v in eta],
            "realised": np.round(realised, 4).tolist(),
            "cost": self.cost,
            "cost_to": self.cost_to,
            "served": self.served,
            "waiting": len(self.requests),
            "fallbacks": self.fallbacks,
            "waves": now.waves,
            "since": self.since,
            "done": self.done,
            "stop": self.stop_reason,
        }
