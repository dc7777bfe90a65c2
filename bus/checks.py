"""What a receiver knows, and the checks a decoded message must pass against it before it is used.

Decoding (:mod:`bus.wire`) checks structure: fields, types, array shapes.
These check values: the number of taxis, node ids within the city, the
minute, the forecast's sizes.  A message that fails is rejected with a
:class:`~bus.wire.WireError` naming the key and the field, and the receiver
drops it; :class:`Rejections` logs the first of each kind and counts the rest,
so a flood of bad messages neither kills a process nor fills its log.
The access rules of :mod:`bus.access` decide who may send; these checks
hold even for a sender that may.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from bus.keys import Keys
from bus.wire import (
    Ack,
    Control,
    Dropoffs,
    ForecastMsg,
    RunSpec,
    SectorForecast,
    State,
    Stop,
    Turn,
    WireError,
)

#: The largest values a sane message carries: minutes a taxi stays busy, and the reported seconds and megabytes.
MAX_BUSY = 24 * 60
MAX_REPORT = 1e7


@dataclass(frozen=True)
class Bounds:
    """What every process of a run knows: the fleet, the city and the episode."""

    taxis: int
    nodes: int
    sectors: int
    minutes: int

    @property
    def hours(self) -> int:
        return (self.minutes + 59) // 60


def _within(where: str, name: str, arr: np.ndarray, lo: int, hi: int) -> None:
    if arr.size and (int(arr.min()) < lo or int(arr.max()) >= hi):
        bad = arr[(arr < lo) | (arr >= hi)][0]
        raise WireError(f"{where}: field {name!r} holds {int(bad)}, outside {lo}..{hi - 1}")


#: The largest run epoch (a coordinator's start in milliseconds since 1970, :mod:`coordinator.runtime`).
MAX_EPOCH = 2**63 - 1


def check_epoch(key: str, epoch: int) -> None:
    """A run epoch is a non-negative 64-bit integer."""
    if not 0 <= epoch <= MAX_EPOCH:
        raise WireError(f"{key}: field 'epoch' is {epoch}, outside 0..2^63-1")


def check_state(msg: State, key: str, b: Bounds) -> State:
    """A state of this run: one entry per taxi, nodes of this city, a minute of the episode."""
    check_epoch(key, msg.epoch)
    if len(msg.pos) != b.taxis:
        raise WireError(f"{key}: field 'pos' has {len(msg.pos)} taxis, the run has {b.taxis}")
    if not 0 <= msg.t <= b.minutes:
        raise WireError(f"{key}: field 't' is {msg.t}, outside the episode's minutes 0..{b.minutes}")
    _within(key, "pos", msg.pos, 0, b.nodes)
    _within(key, "dest", msg.dest, -1, b.nodes)
    _within(key, "tau", msg.tau, 0, MAX_BUSY)
    for name in ("new_pickup", "new_dropoff"):
        _within(key, name, getattr(msg, name), 0, b.nodes)
    _within(key, "new_entry", msg.new_entry, 0, msg.t + 1)
    _within(key, "base", msg.base, -1, b.nodes)
    _within(key, "home", msg.home, -1, b.nodes)
    for name in ("new_index", "picked"):
        arr = getattr(msg, name)
        _within(key, name, arr, 0, np.iinfo(np.int32).max)
        if np.unique(arr).size != arr.size:
            raise WireError(f"{key}: field {name!r} repeats a request")
    if not 0 <= msg.outstanding <= np.iinfo(np.int32).max:
        raise WireError(f"{key}: field 'outstanding' is {msg.outstanding}")
    return msg


def check_forecast(msg: ForecastMsg, key: str, b: Bounds) -> ForecastMsg:
    """A forecast of an hour of this episode, sized for this city, of finite non-negative rates."""
    if not 0 <= msg.hour < b.hours:
        raise WireError(f"{key}: field 'hour' is {msg.hour}, the episode has hours 0..{b.hours - 1}")
    shapes = {"eta": (b.sectors,), "rho": (b.nodes,), "delta": (b.nodes,), "beta": (b.sectors, b.sectors)}
    for name, shape in shapes.items():
        arr = getattr(msg, name)
        if arr.shape != shape:
            raise WireError(f"{key}: field {name!r} has shape {list(arr.shape)}, this city needs {list(shape)}")
        if not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise WireError(f"{key}: field {name!r} holds a negative or non-finite rate")
    return msg


def _rates(key: str, name: str, arr: np.ndarray) -> None:
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise WireError(f"{key}: field {name!r} holds a negative or non-finite rate")


def check_sector_forecast(msg: SectorForecast, key: str, b: Bounds, sector_nodes: Sequence[np.ndarray]) -> SectorForecast:
    """One sector's forecast on its own sector's key, laid out over that sector's intersections (``sector_nodes[sector]``)."""
    if not 0 <= msg.hour < b.hours:
        raise WireError(f"{key}: field 'hour' is {msg.hour}, the episode has hours 0..{b.hours - 1}")
    if Keys.agent_of(key) != msg.sector or not 0 <= msg.sector < b.sectors:
        raise WireError(f"{key}: field 'sector' is {msg.sector}, on the key of sector {Keys.agent_of(key)} of 0..{b.sectors - 1}")
    nodes = sector_nodes[msg.sector]
    if not np.array_equal(msg.nodes, nodes):
        raise WireError(f"{key}: field 'nodes' is not sector {msg.sector}'s {nodes.size} intersections in ascending order")
    for name, size in (("rho", nodes.size), ("delta", nodes.size), ("beta", b.sectors)):
        arr = getattr(msg, name)
        if arr.shape != (size,):
            raise WireError(f"{key}: field {name!r} has shape {list(arr.shape)}, sector {msg.sector} needs [{size}]")
        _rates(key, name, arr)
    _rates(key, "eta", np.array([msg.eta]))
    return msg


def check_dropoffs(msg: Dropoffs, key: str, b: Bounds) -> Dropoffs:
    """The map-wide drop-off distribution of an hour of this episode, one entry per intersection."""
    if not 0 <= msg.hour < b.hours:
        raise WireError(f"{key}: field 'hour' is {msg.hour}, the episode has hours 0..{b.hours - 1}")
    if msg.delta.shape != (b.nodes,):
        raise WireError(f"{key}: field 'delta' has shape {list(msg.delta.shape)}, this city needs [{b.nodes}]")
    _rates(key, "delta", msg.delta)
    return msg


def check_control(msg: Control, key: str, b: Bounds, t: int | None = None) -> Control:
    """A control on its own agent's key, for an agent of this fleet (and minute ``t``), with sane reports."""
    check_epoch(key, msg.epoch)
    if Keys.agent_of(key) != msg.agent:
        raise WireError(f"{key}: control of agent {msg.agent} on another agent's key")
    if not 0 <= msg.agent < b.taxis:
        raise WireError(f"{key}: field 'agent' is {msg.agent}, the run has taxis 0..{b.taxis - 1}")
    if t is not None and msg.t != t:
        raise WireError(f"{key}: field 't' is {msg.t}, the current minute is {t}")
    if msg.by not in ("agent", "base"):
        raise WireError(f"{key}: field 'by' is {msg.by!r}, expected 'agent' or 'base'")
    for name in ("plan_s", "rss_mb"):
        value = getattr(msg, name)
        if not (math.isfinite(value) and 0 <= value <= MAX_REPORT):
            raise WireError(f"{key}: field {name!r} is {value!r}")
    return msg


def check_choice(msg: Control, key: str, candidates: np.ndarray) -> Control:
    """The control is one of the agent's candidate controls at this minute."""
    if msg.control not in candidates.tolist():
        raise WireError(f"{key}: control {msg.control} of agent {msg.agent} is not one of its controls "
                        f"{candidates.tolist()} at minute {msg.t}")
    return msg


def check_turn(msg: Turn, key: str, me: int, b: Bounds, t: int | None) -> Turn:
    """A turn for this agent at the current minute ``t`` or a later one of the episode.

    Zenoh orders samples per key, not across keys: a turn can overtake the
    states before it by many minutes, and the agent holds it until its state.
    """
    check_epoch(key, msg.epoch)
    if msg.agent != me or Keys.agent_of(key) != me:
        raise WireError(f"{key}: a turn for agent {msg.agent}, this is agent {me}")
    if t is not None and msg.t < t:
        raise WireError(f"{key}: field 't' is {msg.t}, the current minute is {t}")
    if not 0 <= msg.t < b.minutes:
        raise WireError(f"{key}: field 't' is {msg.t}, outside the episode's minutes 0..{b.minutes - 1}")
    _within(key, "deps", msg.deps, 0, me)
    if msg.deps.size and np.any(np.diff(msg.deps) <= 0):
        raise WireError(f"{key}: field 'deps' is not ascending without repeats")
    _within(key, "controls", msg.controls, -1, b.nodes)
    return msg


def check_stop(msg: Stop, key: str, b: Bounds) -> Stop:
    """The end of this run: after the episode's last minute (``done``), or earlier with the reason it was ended."""
    check_epoch(key, msg.epoch)
    if msg.reason == "done" and msg.t != b.minutes:
        raise WireError(f"{key}: field 't' is {msg.t}, the run ends after minute {b.minutes}")
    if not 0 <= msg.t <= b.minutes:
        raise WireError(f"{key}: field 't' is {msg.t}, outside the episode's minutes 0..{b.minutes}")
    if len(msg.reason) > 300:
        raise WireError(f"{key}: field 'reason' is {len(msg.reason)} characters long")
    return msg


def check_ack(msg: Ack, key: str, b: Bounds) -> Ack:
    """An acknowledgement on its own agent's key, of a minute of the episode."""
    if Keys.agent_of(key) != msg.agent or not 0 <= msg.agent < b.taxis:
        raise WireError(f"{key}: an ack of agent {msg.agent} on another agent's key")
    if not 0 <= msg.t <= b.minutes:
        raise WireError(f"{key}: field 't' is {msg.t}, outside the episode's minutes 0..{b.minutes}")
    return msg


def check_spec(spec: RunSpec, key: str, settings: Iterable[str]) -> RunSpec:
    """A run spec whose planner settings are among the planner's own ``settings``, with a fleet and an episode."""
    known = set(settings)
    unknown = sorted(map(str, set(spec.rollout) - known))
    if unknown:
        raise WireError(f"{key}: field 'rollout' has unknown settings {', '.join(map(repr, unknown))}; known: {', '.join(sorted(known))}")
    if spec.taxis < 1 or spec.minutes < 1:
        raise WireError(f"{key}: a run of {spec.taxis} taxis and {spec.minutes} minutes")
    if not (math.isfinite(spec.deadline_s) and spec.deadline_s > 0):
        raise WireError(f"{key}: field 'deadline_s' is {spec.deadline_s!r}")
    if not re.fullmatch(r"[0-9a-f]{64}", spec.city_sha256):
        raise WireError(f"{key}: field 'city_sha256' is not 64 hex digits")
    return spec


class Rejections:
    """Dropped messages, by kind: the first of each kind is logged, the rest counted.

    A kind is the rejection with its values taken out (``control/N: field Q is N, …``);
    past :attr:`MAX_KINDS` kinds on one tag, new kinds are counted without a word,
    so that no sender can fill the log.
    """

    MAX_KINDS = 12

    def __init__(self, log: Callable[[str], None]) -> None:
        self._log = log
        self.counts: Counter[str] = Counter()
        self._kinds: Counter[str] = Counter()

    def drop(self, kind: str, why: str) -> None:
        self.counts[kind] += 1
        if self.counts[kind] > 1:
            return
        tag = kind.split(":", 1)[0]
        self._kinds[tag] += 1
        if self._kinds[tag] <= self.MAX_KINDS:
            why = why if len(why) <= 300 else why[:297] + "..."
            self._log(f"ignored: {why} (further messages of this kind are dropped without a word)")
        elif self._kinds[tag] == self.MAX_KINDS + 1:
            self._log(f"ignored: {tag}: more kinds of bad message; they are dropped and counted without a word")

    def exception(self, tag: str, key: str, exc: BaseException) -> None:
        """Drop the message whose handling raised ``exc``: a rejection (:class:`WireError`) or anything else, by its type."""
        if isinstance(exc, WireError):
            self.drop(f"{tag}: {normalize(str(exc))}", str(exc))
        else:
            self.drop(f"{tag}: {type(exc).__name__}", f"{key}: {type(exc).__name__}: {exc}")


def normalize(text: str) -> str:
    """A rejection without its values: quoted text becomes Q, numbers N, and anything bracketed goes."""
    text = re.sub(r"b?'[^']*'|b?\"[^\"]*\"", "Q", text)
    text = re.sub(r"[\[{(].*", "…", text)
    return re.sub(r"[-+]?(inf|nan|\d+(\.\d*)?(e[-+]?\d+)?)", "N", text)
