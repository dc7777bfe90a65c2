"""One coordinator per run: run epochs, the check for a live coordinator, and the takeover fence.

Each coordinator has a run epoch, its start in milliseconds since 1970
(UTC), raised above every epoch it has seen alive on the bus and the one in
the checkpoint it resumes, so that epochs only grow even between hosts whose
clocks disagree.  It holds the liveliness token ``coordinator/<epoch>`` and
puts the epoch in every state, turn, committed control and stop.  Before it
serves anything it asks the router for the run's live coordinator tokens:
with one alive it refuses to start, unless told to take over.  Taking over
declares its own, higher token at once: that token is the fence.  Agents
drop what comes from a lower epoch than the highest they have seen
(:mod:`agents.taxi`), and the old coordinator, on seeing the higher token,
stops (:class:`TakenOver`) without another checkpoint or stop, which also
releases the run directory's lock (:func:`coordinator.checkpoint.locked`)
that the new one waits for.
"""

from __future__ import annotations

import datetime as dt
import logging
import time
from collections.abc import Iterable
from contextlib import ExitStack
from dataclasses import dataclass

from bus.keys import Keys
from city.errors import ConfigError, SurgeError

_logger = logging.getLogger(__name__)

#: Seconds a coordinator asks the router for the run's live coordinator tokens before it starts.
LIVE_QUERY_S = 3.0
#: Seconds a coordinator that takes a run over waits for the fenced one to release the run directory's lock.
TAKEOVER_WAIT_S = 60.0


class TakenOver(SurgeError):
    """A coordinator of a higher run epoch took the run over: this one stops, with no further checkpoint or stop."""


def new_epoch(seen: Iterable[int]) -> int:
    """A run epoch above every one in ``seen``: now in milliseconds since 1970 (UTC), raised if this host's clock is behind."""
    return max([time.time_ns() // 1_000_000, *(e + 1 for e in seen)])


def epoch_time(epoch: int) -> str:
    """When the coordinator of run epoch ``epoch`` started (to the second, UTC)."""
    return dt.datetime.fromtimestamp(epoch / 1000, dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")


def live_epochs(session, keys: Keys) -> list[int]:
    """The run epochs of the run's coordinators whose tokens are alive now."""
    epochs = []
    for reply in session.liveliness().get(keys.all_coordinators, timeout=LIVE_QUERY_S):
        if reply.ok is not None and (e := Keys.agent_of(str(reply.ok.key_expr))) is not None:
            epochs.append(e)
    return epochs


@dataclass(frozen=True)
class Claim:
    """This coordinator's run epoch, and whether it took the run over (its token, the fence, is out already)."""

    epoch: int
    fenced: bool


def claim(session, keys: Keys, stack: ExitStack, *, resume: bool, takeover: bool, resumed_epoch: int = 0) -> Claim:
    """Choose the epoch; refuse a run with a live coordinator, or fence it with ``takeover`` (its token undeclared by ``stack``).

    ``resumed_epoch`` is the epoch of the checkpoint a resumed coordinator starts from.
    """
    live = live_epochs(session, keys)
    epoch = new_epoch([*live, resumed_epoch])
    if not live:
        return Claim(epoch, False)
    old = max(live)
    if not takeover:
        verb = "resume" if resume else "start"
        raise ConfigError(f"run {keys.run!r} has a live coordinator (run epoch {old}, since {epoch_time(old)}): "
                          f"refusing to {verb} a second one, which would drive the same agents; if that coordinator is "
                          f"unreachable rather than dead, --takeover fences it and takes the run over")
    token = session.liveliness().declare_token(keys.coordinator(epoch))
    stack.callback(token.undeclare)
    _logger.warning("taking run %r over from the coordinator of run epoch %d (since %s): its turns are dropped from now on; "
                    "this one is epoch %d", keys.run, old, epoch_time(old), epoch, extra={"who": "coordinator"})
    return Claim(epoch, True)


def taken_over(run: str, by: int, mine: int, minute: int) -> TakenOver:
    """The error a fenced coordinator stops with."""
    return TakenOver(f"run {run!r} was taken over by the coordinator of run epoch {by} (since {epoch_time(by)}); "
                     f"this one (epoch {mine}) stops at minute {minute} without writing its checkpoint again")
