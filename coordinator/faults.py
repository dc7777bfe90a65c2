"""What the coordinator knows of its agents' health, and how it tells one agent's failure from a partition.

- An agent is *alive* while its liveliness token is present.
- An agent that missed a deadline is *suspect*: its later turns are still
  sent, but the coordinator does not wait for them, so a hung agent costs
  one deadline, not one per minute.  It is waited for again once it
  acknowledges the current minute (an :class:`~bus.wire.Ack` of the
  minute's state, or a control for it), which a recovered agent does as
  soon as it has caught up.
- Losing most tokens (more than half the fleet) is a *partition*, not a
  mass failure: a restarted router or a cut link makes every token vanish
  at once, and giving every taxi its base control would race through the
  episode.  The clock pauses instead, until the agents that left in that
  burst are back and have acknowledged the minute, or until the partition
  timeout ends the run with one line.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from city.errors import SurgeError

#: Seconds to let a burst of departures arrive before telling one agent's loss from a partition.
SETTLE_S = 0.5
#: Departures this close to the latest one belong to the same partition.
BURST_S = 5.0
#: Seconds between re-sent turns: a turn published while the router was away, or before it knew the agent's subscriber, is lost.
RESEND_S = 2.0
#: Seconds to wait, once a partition's tokens are back, for those agents to acknowledge the minute (from a snapshot).
ACK_WAIT_S = 10.0


class PartitionError(SurgeError):
    """The agents of a partition did not come back within the partition timeout."""


@dataclass
class Health:
    """Alive, suspect and acknowledged agents of a fleet of ``taxis``; ``log`` says what changed, in one line each."""

    taxis: int
    log: Callable[[str], None]
    alive: set[int] = field(default_factory=set)
    suspect: set[int] = field(default_factory=set)
    #: The latest minute each agent acknowledged.
    acked: dict[int, int] = field(default_factory=dict)
    #: When each agent's token last went (monotonic seconds).
    departed: dict[int, float] = field(default_factory=dict)
    #: When the last token went.
    last_departure: float = float("-inf")

    def token(self, agent: int, present: bool, running: bool) -> None:
        """Agent ``agent``'s token appeared (``present``) or went; ``running``: after every agent first joined."""
        if present:
            if running and agent not in self.alive:
                self.log(f"agent {agent} is back")
            self.alive.add(agent)
        elif agent in self.alive:
            self.alive.discard(agent)
            self.last_departure = self.departed[agent] = time.monotonic()
            self.log(f"agent {agent} left")

    def ack(self, agent: int, t: int, current: int | None) -> None:
        """Agent ``agent`` holds minute ``t``; a suspect that holds the ``current`` minute is waited for again."""
        self.acked[agent] = max(t, self.acked.get(agent, -1))
        if agent in self.suspect and current is not None and t >= current:
            self.suspect.discard(agent)
            self.log(f"agent {agent} acknowledged minute {t}; its turns are waited for again")

    def lost_since(self, agent: int, when: float) -> bool:
        """Whether agent ``agent``'s token is gone, or went and came back, since ``when`` (monotonic seconds).

        A turn sent before such a departure went with the process that left: a
        process that came back in its place subscribed after it, and would
        only let the turn's deadline pass.
        """
        return agent not in self.alive or self.departed.get(agent, float("-inf")) >= when

    def missed(self, agents: set[int], t: int, deadline_s: float) -> None:
        """``agents`` let the deadline of minute ``t`` pass: suspect, in one log line however many."""
        self.suspect |= agents
        self.log(f"minute {t}: {agents_text(agents)} silent for {deadline_s:g} s; base control used; "
                 f"{'it is' if len(agents) == 1 else 'each is'} suspect (no further wait) until it acknowledges the current minute")

    def partitioned(self) -> bool:
        """Most of the fleet's tokens are gone."""
        return 2 * len(self.alive) < self.taxis

    def partition(self) -> set[int]:
        """The agents of the current partition: those alive, and those gone in the burst of departures that made it."""
        return self.alive | {a for a, when in self.departed.items() if when >= self.last_departure - BURST_S and a not in self.alive}

    def healed(self, expected: set[int], t: int) -> tuple[bool, bool]:
        """(every agent of ``expected`` is back, and each of them has acknowledged minute ``t``)."""
        back = expected <= self.alive
        return back, back and all(self.acked.get(a, -1) >= t for a in expected)


def agents_text(ids: set[int]) -> str:
    """``agent 3``, ``agents 3, 5`` or ``agents 0, 1, … and 90 more``: a log line stays one short line."""
    ids_ = sorted(ids)
    if len(ids_) == 1:
        return f"agent {ids_[0]}"
    more = f" and {len(ids_) - 10} more" if len(ids_) > 10 else ""
    return f"agents {', '.join(map(str, ids_[:10]))}{more}"
