"""The key-expression scheme of one run: everything lives under ``surge/<run>/``.

:data:`SCHEME` is the one table of the run's keys: what each carries, which
role writes it and which roles read it.  :class:`Keys` builds key
expressions only from it, and :mod:`bus.access` writes the router's
access-control rules from it, so a key and its rule cannot drift apart.

=========================  ==========================  ==============================
key                        who writes                  what
=========================  ==========================  ==============================
``spec``                   coordinator (queryable)     :class:`~bus.wire.RunSpec`
``snapshot``               coordinator (queryable)     :class:`~bus.wire.Snapshot`
``state``                  coordinator                 :class:`~bus.wire.State` each minute
``forecast/<sector>``      coordinator or predictor    :class:`~bus.wire.SectorForecast` each hour;
                           (coordinator answers)       the coordinator answers queries for the current hour
``dropoffs``               coordinator or predictor    :class:`~bus.wire.Dropoffs` each hour
``turn/<agent>``           coordinator                 :class:`~bus.wire.Turn`
``control/<agent>``        agent                       proposed :class:`~bus.wire.Control`
``committed/<agent>``      coordinator                 committed :class:`~bus.wire.Control`
``alive/<agent>``          agent (liveliness token)    present while the agent runs
``predictor``              predictor (queryable)       :class:`~bus.wire.ForecastMsg` for a :class:`~bus.wire.ForecastRequest`
``stop``                   coordinator                 :class:`~bus.wire.Stop`
``coordinator/<epoch>``    coordinator (liveliness)    present while the coordinator of run epoch ``<epoch>`` runs
``ack/<agent>``            agent                       :class:`~bus.wire.Ack`: the agent holds minute ``t``'s state
=========================  ==========================  ==============================

The forecast keys have two possible writers: the predictor service when the
run has one, else the coordinator.  A coordinator also reads the
``coordinator/*`` tokens: a live one of another epoch means the run has a
coordinator already (refused, unless ``--takeover``), or a newer one has
taken the run over (this one stops).  ``docs/PROTOCOL.md`` is this table for a
third party, with every message's fields.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from city.errors import ConfigError

PREFIX = "surge"
_RUN = re.compile(r"^[A-Za-z0-9_.-]+$")

#: Roles on the bus; a taxi's identity is ``taxi-<i>`` (see :mod:`bus.certs`).
COORDINATOR, PREDICTOR, TAXI = "coordinator", "predictor", "taxi"
#: A read-only follower of a whole run (``surge watch``, a dashboard): it reads every key it needs and writes none.
OBSERVER = "observer"
#: How a key is used: published samples, a queryable that answers queries, or liveliness tokens.
PUB, QUERYABLE, TOKEN = "pub", "queryable", "token"


@dataclass(frozen=True)
class Channel:
    """One key of the scheme.

    ``per_agent`` keys end in an agent index, ``per_sector`` keys in a
    sector index, ``per_epoch`` keys in a run epoch.  A taxi writes only its own per-agent keys; with
    ``own_only`` it also reads only its own.  ``also_written_by`` are roles
    that may publish on the key besides ``writer``; ``answered_by`` is a role
    that also answers the readers' queries on it.
    """

    name: str
    per_agent: bool
    use: str
    writer: str
    readers: tuple[str, ...]
    own_only: bool = False
    per_sector: bool = False
    per_epoch: bool = False
    also_written_by: tuple[str, ...] = ()
    answered_by: str | None = None

    @property
    def writers(self) -> tuple[str, ...]:
        return (self.writer, *self.also_written_by)

    @property
    def indexed(self) -> bool:
        """The key ends in an index (an agent's, a sector's or an epoch)."""
        return self.per_agent or self.per_sector or self.per_epoch


SCHEME: tuple[Channel, ...] = (
    Channel("spec", False, QUERYABLE, COORDINATOR, (TAXI, OBSERVER)),
    Channel("snapshot", False, QUERYABLE, COORDINATOR, (TAXI, OBSERVER)),
    Channel("state", False, PUB, COORDINATOR, (TAXI, OBSERVER)),
    Channel("forecast", False, PUB, COORDINATOR, (TAXI, OBSERVER), per_sector=True, also_written_by=(PREDICTOR,),
            answered_by=COORDINATOR),
    Channel("dropoffs", False, PUB, COORDINATOR, (TAXI, OBSERVER), also_written_by=(PREDICTOR,)),
    Channel("turn", True, PUB, COORDINATOR, (TAXI, OBSERVER), own_only=True),
    Channel("control", True, PUB, TAXI, (COORDINATOR,)),
    Channel("committed", True, PUB, COORDINATOR, (TAXI, OBSERVER)),
    Channel("alive", True, TOKEN, TAXI, (COORDINATOR, OBSERVER)),
    Channel("predictor", False, QUERYABLE, PREDICTOR, (COORDINATOR,)),
    Channel("stop", False, PUB, COORDINATOR, (TAXI, OBSERVER)),
    Channel("coordinator", False, TOKEN, COORDINATOR, (TAXI, COORDINATOR, OBSERVER), per_epoch=True),
    Channel("ack", True, PUB, TAXI, (COORDINATOR,)),
)

#: What an observer subscribes to, key by key below ``surge/<run>/``.  On a secured bus the
#: router admits a subscription only if its key expression is included in a rule's (zenoh's
#: access control matches by inclusion), so ``surge/<run>/**``, wider than every rule, is
#: refused without a word to the client; these keys are each within the observer's rules.
OBSERVED = ("state", "forecast/*", "turn/*", "committed/*", "stop")
CHANNELS = {c.name: c for c in SCHEME}


def root(run: str | None) -> str:
    """``surge/<run>``; ``None`` stands for every run (``surge/*``, for access rules)."""
    if run is None:
        return f"{PREFIX}/*"
    if not _RUN.match(run):
        raise ConfigError(f"run name {run!r}: use letters, digits, '_', '.' or '-'")
    return f"{PREFIX}/{run}"


def key(run_root: str, name: str, agent: int | str | None = None) -> str:
    """The key of channel ``name`` (for agent or sector ``agent``, an index or ``*``, on an indexed channel)."""
    channel = CHANNELS[name]
    if channel.indexed != (agent is not None):
        raise ValueError(f"channel {name!r} {'needs' if channel.indexed else 'takes no'} index")
    return f"{run_root}/{name}" if agent is None else f"{run_root}/{name}/{agent}"


class Keys:
    """Key expressions of run ``run``, built from :data:`SCHEME`."""

    def __init__(self, run: str) -> None:
        self.run = run
        self.root = root(run)
        self.spec = key(self.root, "spec")
        self.snapshot = key(self.root, "snapshot")
        self.state = key(self.root, "state")
        self.dropoffs = key(self.root, "dropoffs")
        self.all_forecasts = key(self.root, "forecast", "*")
        self.stop = key(self.root, "stop")
        self.predictor = key(self.root, "predictor")
        self.all_controls = key(self.root, "control", "*")
        self.all_committed = key(self.root, "committed", "*")
        self.all_alive = key(self.root, "alive", "*")
        self.all_coordinators = key(self.root, "coordinator", "*")
        self.all_acks = key(self.root, "ack", "*")

    def forecast(self, sector: int) -> str:
        return key(self.root, "forecast", sector)

    def turn(self, agent: int) -> str:
        return key(self.root, "turn", agent)

    def control(self, agent: int) -> str:
        return key(self.root, "control", agent)

    def committed(self, agent: int) -> str:
        return key(self.root, "committed", agent)

    def alive(self, agent: int) -> str:
        return key(self.root, "alive", agent)

    def ack(self, agent: int) -> str:
        return key(self.root, "ack", agent)

    def coordinator(self, epoch: int) -> str:
        """The liveliness token of the run's coordinator of run epoch ``epoch``."""
        return key(self.root, "coordinator", epoch)

    @staticmethod
    def agent_of(key: str) -> int | None:
        """The agent (or sector) index an indexed key ends with, or ``None``."""
        last = str(key).rsplit("/", 1)[-1]
        return int(last) if last.isdigit() else None
