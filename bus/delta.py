"""Per-minute state deltas: the coordinator encodes an observation against the previous one, agents rebuild it.

The static city is never sent; each minute carries the fleet (a few hundred
bytes) and only the requests that entered or were picked up.  A receiver that
missed a minute, or whose count of outstanding requests disagrees, asks for a
snapshot instead of guessing.
"""

from __future__ import annotations

import numpy as np

from bus.wire import State
from city.sim import Observation


def state_message(obs: Observation, previous: np.ndarray | None, base: np.ndarray, epoch: int = 0, home: np.ndarray | None = None) -> State:
    """The state of minute ``obs.t`` as a delta against the outstanding request indices ``previous``, with the minute's ``base`` controls.

    ``previous=None`` gives a full state; ``epoch`` is the sending coordinator's run epoch; ``home``
    the ``rebalance`` base's targets (none by default).
    """
    full = previous is None
    now = np.asarray(obs.req_index, dtype=np.int64)
    new = np.ones(now.size, dtype=bool) if full else ~np.isin(now, previous)
    picked = np.empty(0, dtype=np.int32) if full else np.setdiff1d(previous, now).astype(np.int32)
    return State(
        t=int(obs.t), full=full, pos=obs.pos, tau=obs.tau, dest=obs.dest,
        new_index=now[new].astype(np.int32), new_pickup=obs.req_pickup[new], new_dropoff=obs.req_dropoff[new],
        new_entry=obs.req_entry[new], picked=picked, outstanding=int(now.size), base=base,
        home=np.empty(0, dtype=np.int32) if home is None else home, epoch=epoch,
    )


class StateView:
    """An agent's copy of the world state, kept up to date from :class:`~bus.wire.State` messages."""

    def __init__(self) -> None:
        self.obs: Observation | None = None
        #: The base policy's joint control of minute ``obs.t``, as the coordinator computed it, and the ``rebalance`` base's targets.
        self.base: np.ndarray | None = None
        self.home: np.ndarray | None = None
        self._req: dict[int, tuple[int, int, int]] = {}

    def apply(self, msg: State) -> bool:
        """Apply a state; ``False`` when it cannot be (a gap, or a mismatch): ask for a snapshot then."""
        if msg.full:
            self._req = {}
        elif self.obs is None or msg.t != self.obs.t + 1:
            return False
        for i in msg.picked.tolist():
            self._req.pop(i, None)
        for i, p, d, e in zip(msg.new_index.tolist(), msg.new_pickup.tolist(), msg.new_dropoff.tolist(), msg.new_entry.tolist()):
            self._req[i] = (p, d, e)
        if len(self._req) != msg.outstanding:
            self.obs = None
            return False
        idx = np.array(sorted(self._req), dtype=np.int64)
        rows = np.array([self._req[i] for i in idx.tolist()], dtype=np.int32).reshape(-1, 3)
        self.obs = Observation(
            t=msg.t, pos=msg.pos, tau=msg.tau, dest=msg.dest, req_index=idx,
            req_pickup=np.ascontiguousarray(rows[:, 0]), req_dropoff=np.ascontiguousarray(rows[:, 1]),
            req_entry=np.ascontiguousarray(rows[:, 2]),
        )
        self.base = msg.base
        self.home = msg.home
        return True
