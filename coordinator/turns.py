"""The coordinator's turn-taking within a minute: turns out in waves, controls in, commitments out, partitions waited out.

A mixin of :class:`coordinator.runtime.Coordinator`, whose state (``waiting``,
``arrived``, ``health``, ``tally``) and message handling (``_handle``) it uses.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from agents.waves import Waves
from bus.session import Inbox
from bus.wire import Control, Turn
from coordinator.faults import ACK_WAIT_S, RESEND_S, SETTLE_S, PartitionError, agents_text

_logger = logging.getLogger(__name__)


def log(message: str, level: int = logging.INFO) -> None:
    """A line of the coordinator: ``surge coordinator: …``."""
    _logger.log(level, "%s", message, extra={"who": "coordinator"})


class TurnTaking:
    """Sending each wave's turns, taking its controls, and pausing the clock while the fleet is partitioned."""

    def _pace(self, inbox: Inbox, until: float) -> None:
        """Wait until ``until`` (``perf_counter`` seconds), still serving joins and snapshots and taking the wave's controls."""
        while (left := until - time.perf_counter()) > 0:
            self._receive(inbox, left)

    def _receive(self, inbox: Inbox, timeout: float) -> None:
        """Handle the next item, if one comes within ``timeout`` s; a control of an agent in ``waiting`` goes to ``arrived``.

        Every wait takes the wave's controls, so one that comes while the
        clock is paused for a partition is not lost.
        """
        item = inbox.get(timeout=timeout)
        if item is None:
            return
        t = -1 if self.obs is None else int(self.obs.t)
        c = self._handle(item, {(t, a) for a in self.waiting})
        if c is not None:
            self.waiting.discard(c.agent)
            self.arrived[c.agent] = c

    def _turns(self, inbox: Inbox, pubs: dict, commit_pubs: dict, t: int, waves: Waves, base: np.ndarray, u: np.ndarray) -> list[dict]:
        """Play minute ``t``'s turns: each agent's goes out as soon as the predecessors it depends on have committed.

        No wave waits for the slowest agent of the one before: an agent is
        released when its own ``depends`` are in ``u``, with their controls,
        and its control is committed the moment it comes, which may release
        others.  The decisions are those of strictly sequential turns, since
        an agent's costs depend only on its ``depends`` (:mod:`agents.waves`).
        Suspect agents' turns are sent but not waited for.  A departure that
        turns out to be a partition pauses the clock, and the unanswered turns
        go out again once the agents are back; they also go out again every
        :data:`~coordinator.faults.RESEND_S` seconds, and an agent answers a
        turn it has planned with the control it sent.  An agent that is gone,
        that left since its turn went out (a process back in its place never
        got the turn), suspect or past its deadline gets the base control.

        Returns the minute's waves for the report: each wave's agents, their
        planning seconds, and the seconds by which the wave's last commit
        came after the waves before it (the minute's time in turns, split so
        that the waves' seconds add up to it).
        """
        health, tally = self.health, self.tally
        agents = waves.agents.tolist()
        depends = dict(zip(agents, waves.depends))
        blocking = {a: set(depends[a].tolist()) for a in agents}
        dependents = waves.dependents()
        ready = [a for a in agents if not blocking[a]]
        turns: dict[int, bytes] = {}
        sent: dict[int, float] = {}
        deadline: dict[int, float] = {}
        done: dict[int, float] = {}
        plan_s: dict[int, float | None] = {}
        self.arrived, self.waiting = {}, set()
        t0 = time.perf_counter()

        def commit(agent: int, c: Control | None) -> None:
            if c is None:
                tally.fallbacks[agent] += 1
                tally.fallen.append([t, agent])
                c = Control(t=t, agent=agent, control=int(base[agent]), epoch=self.epoch, by="base")
            else:
                u[agent] = c.control
                tally.planned[agent] += 1
                tally.plan_s.append(c.plan_s)
                tally.rss[agent] = max(tally.rss[agent], c.rss_mb)
            commit_pubs[agent].put(c.encode())
            done[agent], plan_s[agent] = time.perf_counter(), None if c.by == "base" else c.plan_s
            self.waiting.discard(agent)
            for j in dependents[agent]:
                blocking[j].discard(agent)
                if not blocking[j]:
                    ready.append(j)

        def lost() -> set[int]:  # waiting agents gone, or gone and back, since their turn went out
            return {a for a in self.waiting if health.lost_since(a, sent[a])}

        def again(agents: set[int]) -> None:  # after a partition healed: what was sent meanwhile is lost, and the clock did not run
            now = time.monotonic()
            for a in sorted(agents):
                pubs[a].put(turns[a])
                sent[a], deadline[a] = now, now + self.cfg.deadline_s

        while ready or self.waiting:
            if ready:
                # No turn is released into a partition: the clock waits for it to heal.
                if (health.partitioned() or not set(ready) <= health.alive) and self._partition(inbox, t):
                    again(self.waiting)
                release, ready[:] = sorted(ready), []
                now = time.monotonic()
                for a in release:
                    if a not in health.alive:
                        commit(a, None)
                        continue
                    turns[a] = Turn(t=t, agent=a, deps=depends[a], controls=u[depends[a]], epoch=self.epoch).encode()
                    pubs[a].put(turns[a])
                    if a in health.suspect:
                        commit(a, None)
                    else:
                        self.waiting.add(a)
                        sent[a], deadline[a] = now, now + self.cfg.deadline_s
            elif lost():
                healed = self._partition(inbox, t)
                gone = self.waiting - health.alive if healed else lost()  # again: more may have left while it settled
                if gone:
                    log(f"minute {t}: {agents_text(gone)} gone; base control used")
                    for a in sorted(gone):
                        commit(a, None)
                if healed:
                    again(self.waiting)
            else:
                now = time.monotonic()
                late = {a for a in self.waiting if now >= deadline[a]}
                if late:
                    health.missed(late, t, self.cfg.deadline_s)
                    for a in sorted(late):
                        commit(a, None)  # a late control is stale, not this minute's
                    continue
                for a in sorted(a for a in self.waiting if now - sent[a] >= RESEND_S):
                    pubs[a].put(turns[a])
                    sent[a] = now
                until = min(min(deadline[a] for a in self.waiting), min(sent[a] for a in self.waiting) + RESEND_S)
                self._receive(inbox, max(0.0, until - now))
            for a in sorted(self.arrived):
                commit(a, self.arrived[a])
            self.arrived = {}
        out, before = [], t0
        for group in waves.groups():
            members = group.tolist()
            end = max(before, *(done[a] for a in members))
            out.append({"seconds": end - before, "agents": members, "plan_s": [plan_s[a] for a in members]})
            before = end
        return out

    def _partition(self, inbox: Inbox, t: int) -> bool:
        """Whether the fleet is partitioned, after letting a burst of departures arrive; if so, wait until it heals.

        ``False``: the departures are those of single agents, and the run goes
        on without them.  ``True``: the agents of the partition (alive, or gone
        in its burst) are back and hold minute ``t``, or the ack wait ran out.
        """
        health = self.health
        while (left := health.last_departure + SETTLE_S - time.monotonic()) > 0:
            self._pace(inbox, time.perf_counter() + left)
        expected = health.partition()
        if not health.partitioned() or expected <= health.alive:
            return False  # single departures, or a fleet worn down one agent at a time: nobody to wait for
        for a in expected:
            health.acked.pop(a, None)  # the acks that count are those of the agents' snapshots after the partition
        timeout, gone = self.cfg.partition_timeout_s, self.cfg.taxis - len(health.alive)
        log(f"minute {t}: partition: {gone} of {self.cfg.taxis} agents' tokens are gone; "
            f"the clock pauses until they return (at most {timeout:g} s)")
        start = time.monotonic()
        acked_by = None
        while True:
            back, acked = health.healed(expected, t)
            now = time.monotonic()
            if back and acked_by is None:
                acked_by = now + ACK_WAIT_S
            if acked or (acked_by is not None and now >= acked_by):
                log(f"minute {t}: partition healed after {now - start:.1f} s: {len(health.alive)} agents back; minute {t} goes on")
                self.tally.partitions.append({"minute": t, "tokens_gone": gone, "paused_s": now - start})
                return True
            if now - start >= timeout:
                raise PartitionError(f"run {self.cfg.run!r}: partition at minute {t}: {len(expected & health.alive)} of "
                                     f"{len(expected)} agents returned within {timeout:g} s; the run ends")
            self._pace(inbox, time.perf_counter() + 0.2)
