"""What a distributed run costs on the bus, and what its waves project for more hosts.

The coordinator counts every message it sends and receives (:class:`Traffic`):
with agents that talk only to it, that is the run's whole traffic through the
router.  :func:`project_minutes` turns each minute's waves and each agent's
planning time into the minute a fleet spread over more hosts would take.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class Traffic:
    """Messages and payload bytes through one process's session."""

    sent_messages: int = 0
    sent_bytes: int = 0
    received_messages: int = 0
    received_bytes: int = 0

    def sent(self, payload: bytes) -> None:
        self.sent_messages += 1
        self.sent_bytes += len(payload)

    def received(self, payload: bytes) -> None:
        self.received_messages += 1
        self.received_bytes += len(payload)

    def summary(self, minutes: int) -> dict:
        """Totals, and per simulated minute."""
        total = {k: getattr(self, k) for k in ("sent_messages", "sent_bytes", "received_messages", "received_bytes")}
        messages, size = self.sent_messages + self.received_messages, self.sent_bytes + self.received_bytes
        return {**total, "messages_per_minute": messages / max(minutes, 1), "bytes_per_minute": size / max(minutes, 1)}


class Counted:
    """A publisher whose puts are counted in a :class:`Traffic`."""

    def __init__(self, publisher: Any, traffic: Traffic) -> None:
        self._pub, self._traffic = publisher, traffic

    def put(self, payload: bytes) -> None:
        self._traffic.sent(payload)
        self._pub.put(payload)


def host_of(agent: int, taxis: int, hosts: int) -> int:
    """The host of ``agent`` when the fleet is split into ``hosts`` contiguous blocks (``surge agents --ids 0-49`` …)."""
    return agent * hosts // taxis


def project_minutes(waves: list[list[dict]], plan_s: dict[tuple[int, int], float], overhead_s: list[float], taxis: int,
                    hosts: int | None) -> list[float]:
    """Each minute's projected wall time with the agents on ``hosts`` hosts like this one (``None``: one host per agent).

    Anchored on the run measured here, on one host: a wave's agents on one
    host share its cores, so a host's part of a wave takes the wave's measured
    time in proportion to the wave's agents it holds, but never less than
    the slowest of them planning alone (``plan_s``, from the sequential run).
    The waves of a minute follow each other, and the rest of the minute
    (``overhead_s[t]``: the state, base controls, waves, the simulator step)
    stays as measured.  With ``hosts=1`` this gives back the measured minute
    (or the sequential agents' time, when that is longer).

    Parameters
    ----------
    waves : list of list of dict
        Per minute, its waves as the coordinator reports them (``agents`` and ``seconds``).
    plan_s : dict
        Seconds each ``(minute, agent)`` took to plan alone.
    overhead_s : list of float
        Per minute, the seconds outside the waves.
    taxis, hosts : int
    """
    out = []
    for t, minute in enumerate(waves):
        total = overhead_s[t]
        for wave in minute:
            agents = wave["agents"]
            per_host: dict[int, int] = {}
            for a in agents:
                h = a if hosts is None else host_of(a, taxis, hosts)
                per_host[h] = per_host.get(h, 0) + 1
            share = max(per_host.values(), default=0) / max(len(agents), 1)
            alone = max((plan_s.get((t, a), 0.0) for a in agents), default=0.0)
            total += max(wave["seconds"] * share, alone)
        out.append(total)
    return out


def median(xs: list[float]) -> float | None:
    return float(np.median(xs)) if xs else None
