"""The wire format: msgpack messages with a schema version, checked field by field on decode.

Every message is a msgpack map ``{"v": WIRE_VERSION, "kind": ..., <fields>}``.
Integer arrays travel as little-endian int32 bytes and float arrays as
little-endian float64 bytes with their shape, so an agent rebuilds exactly
the arrays the coordinator holds and the rollout's decisions match the
in-process run bit for bit.  A message that does not decode raises
:class:`WireError` naming the key expression and the field; receivers log it
in one line and go on.  ``docs/PROTOCOL.md`` is the same format written for
a third party, with the versioning rules.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import msgpack
import numpy as np

from city.errors import SurgeError

#: The zenoh encoding every payload of the run carries.
ENCODING = "application/msgpack"
#: Bumped whenever a message gains, loses or changes a field (docs/PROTOCOL.md, versioning).
#: Version 3 added the run epoch to State, Turn, Control and Stop; version 4 the ``rebalance`` base's targets to State.
WIRE_VERSION = 4


class WireError(SurgeError, ValueError):
    """A message on the bus that cannot be decoded: wrong version, kind, field or type."""


I32 = "i32"  # 1-D int32 array
F64 = "f64"  # float64 array of any shape


@dataclass(frozen=True)
class Message:
    """Base of every message; subclasses declare ``kind`` and typed fields."""

    kind: ClassVar[str] = ""
    #: Field name -> I32 or F64, for the array fields.
    arrays: ClassVar[dict[str, str]] = {}

    def encode(self) -> bytes:
        out: dict[str, Any] = {"v": WIRE_VERSION, "kind": self.kind}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            code = self.arrays.get(f.name)
            if code == I32:
                out[f.name] = np.ascontiguousarray(value, dtype="<i4").tobytes()
            elif code == F64:
                arr = np.ascontiguousarray(value, dtype="<f8")
                out[f.name] = {"shape": list(arr.shape), "data": arr.tobytes()}
            else:
                out[f.name] = value
        return msgpack.packb(out, use_bin_type=True)


def _array(code: str, raw: Any, where: str) -> np.ndarray:
    if code == I32:
        if not isinstance(raw, bytes) or len(raw) % 4:
            raise WireError(f"{where}: expected int32 bytes")
        return np.frombuffer(raw, dtype="<i4").astype(np.int32)
    if not isinstance(raw, dict) or not isinstance(raw.get("data"), bytes) or not isinstance(raw.get("shape"), list):
        raise WireError(f"{where}: expected {{shape, data}} of float64")
    shape = raw["shape"]
    if (len(shape) > 4 or not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape)
            or math.prod(shape) * 8 != len(raw["data"])):
        raise WireError(f"{where}: shape {shape} does not match {len(raw['data'])} bytes of float64")
    return np.frombuffer(raw["data"], dtype="<f8").reshape(shape).astype(np.float64)


#: Annotation (a string, under ``from __future__ import annotations``) -> accepted Python types.
_PLAIN: dict[str, type | tuple[type, ...]] = {
    "int": int, "str": str, "bool": bool, "float": (int, float), "dict": dict, "bytes": bytes, "str | None": (str, type(None)),
}


def _short(value: Any) -> str:
    """A received value as an error message shows it: short, whatever the sender put there."""
    if isinstance(value, bytes):
        return f"{len(value)} bytes"
    if isinstance(value, str):
        return repr(value if len(value) <= 30 else value[:27] + "...")
    if value is None or isinstance(value, (bool, int, float)):
        return repr(value)
    return f"a {type(value).__name__}"


def decode(payload: bytes, expect: type[Message] | tuple[type[Message], ...], key: str = "") -> Message:
    """Decode ``payload`` as one of ``expect``; raise :class:`WireError` naming ``key`` and the bad field."""
    expect = expect if isinstance(expect, tuple) else (expect,)
    where = key or "message"
    try:
        raw = msgpack.unpackb(payload, raw=False)
    except Exception as exc:  # msgpack raises several unrelated types on garbage
        raise WireError(f"{where}: not msgpack ({type(exc).__name__})") from None
    if not isinstance(raw, dict):
        raise WireError(f"{where}: expected a map, got {type(raw).__name__}")
    if raw.get("v") != WIRE_VERSION:
        raise WireError(f"{where}: wire version {_short(raw.get('v'))}, expected {WIRE_VERSION}")
    by_kind = {cls.kind: cls for cls in expect}
    cls = by_kind.get(raw.get("kind"))  # type: ignore[arg-type]
    if cls is None:
        raise WireError(f"{where}: kind {_short(raw.get('kind'))}, expected {' or '.join(by_kind)}")
    names = {f.name for f in dataclasses.fields(cls)}
    extra = sorted(map(str, set(raw) - names - {"v", "kind"}))
    if extra:
        raise WireError(f"{where}: {cls.kind} has no field {_short(extra[0])}")
    values = {}
    for f in dataclasses.fields(cls):
        if f.name not in raw:
            if f.default is not dataclasses.MISSING:
                continue
            raise WireError(f"{where}: {cls.kind} has no field {f.name!r}")
        code = cls.arrays.get(f.name)
        if code:
            values[f.name] = _array(code, raw[f.name], f"{where}: field {f.name!r}")
            continue
        want = _PLAIN[f.type]
        value = raw[f.name]
        if not isinstance(value, want) or (isinstance(value, bool) and f.type != "bool"):
            raise WireError(f"{where}: field {f.name!r} is {type(value).__name__}, expected {f.type}")
        values[f.name] = value
    try:
        return cls(**values)
    except ValueError as exc:
        raise WireError(f"{where}: {exc}") from None


@dataclass(frozen=True)
class RunSpec(Message):
    """What an agent needs to join a run: the static city by name, the episode and the planner's settings.

    The city itself is not sent: every host builds it from ``scenario`` (and
    ``data_dir`` for real maps), once, from its on-disk cache.  ``city_sha256``
    (:func:`city.fingerprint.city_sha256`) lets an agent refuse a city that is
    not the coordinator's even when its sizes agree; ``code`` names the
    coordinator's code, so a host running other code can say so.
    """

    kind: ClassVar[str] = "spec"
    run: str
    scenario: str
    data_dir: str | None
    city: dict
    taxis: int
    minutes: int
    policy: str
    rollout: dict
    deadline_s: float
    city_sha256: str
    code: str


@dataclass(frozen=True)
class ForecastMsg(Message):
    """The demand of one hour of the episode (``hour`` counts from the episode's start)."""

    kind: ClassVar[str] = "forecast"
    arrays: ClassVar[dict[str, str]] = {"eta": F64, "rho": F64, "delta": F64, "beta": F64}
    hour: int
    eta: np.ndarray
    rho: np.ndarray
    delta: np.ndarray
    beta: np.ndarray


@dataclass(frozen=True)
class SectorForecast(Message):
    """Sector ``sector``'s part of the forecast of hour ``hour``: η, and ρ, δ over ``nodes``, and β's row."""

    kind: ClassVar[str] = "sector-forecast"
    arrays: ClassVar[dict[str, str]] = {"nodes": I32, "rho": F64, "delta": F64, "beta": F64}
    hour: int
    sector: int
    eta: float
    nodes: np.ndarray
    rho: np.ndarray
    delta: np.ndarray
    beta: np.ndarray


@dataclass(frozen=True)
class Dropoffs(Message):
    """What a local rollout needs of hour ``hour``'s forecast beyond its own sectors: the drop-off distribution δ over the map."""

    kind: ClassVar[str] = "dropoffs"
    arrays: ClassVar[dict[str, str]] = {"delta": F64}
    hour: int
    delta: np.ndarray


@dataclass(frozen=True)
class ForecastRequest(Message):
    """The coordinator asks the predictor service for the forecast of hour ``hour`` of the episode, starting at ``when``."""

    kind: ClassVar[str] = "forecast-request"
    hour: int
    when: str

    def __post_init__(self) -> None:
        import datetime as dt

        try:
            dt.datetime.fromisoformat(self.when)
        except ValueError:
            raise ValueError(f"field 'when': {_short(self.when)} is not an ISO date and time") from None


@dataclass(frozen=True)
class State(Message):
    """The fleet at minute ``t`` and the change in outstanding requests since ``t - 1``.

    ``full`` states (answers to a snapshot query) list every outstanding
    request in ``new_*`` and nothing in ``picked``; per-minute states list the
    requests that entered at ``t`` and those picked up during minute ``t - 1``.
    ``outstanding`` lets a receiver check that its copy kept up.  ``base`` is
    the base policy's joint control for minute ``t`` (a node id per taxi, or
    −1 for a pickup; a busy taxi's next hop), computed once by the
    coordinator so that no agent recomputes it; with the ``rebalance`` base,
    ``home`` is each taxi's rebalancing target of the minute (-1: none),
    empty for the other bases.  ``epoch`` is the run epoch
    of the coordinator that sent it (:attr:`Turn.epoch`).
    """

    kind: ClassVar[str] = "state"
    arrays: ClassVar[dict[str, str]] = {
        "pos": I32, "tau": I32, "dest": I32, "new_index": I32, "new_pickup": I32, "new_dropoff": I32, "new_entry": I32, "picked": I32,
        "base": I32, "home": I32,
    }
    t: int
    full: bool
    pos: np.ndarray
    tau: np.ndarray
    dest: np.ndarray
    new_index: np.ndarray
    new_pickup: np.ndarray
    new_dropoff: np.ndarray
    new_entry: np.ndarray
    picked: np.ndarray
    outstanding: int
    base: np.ndarray
    home: np.ndarray
    epoch: int

    def __post_init__(self) -> None:
        m, k = len(self.pos), len(self.new_index)
        if len(self.tau) != m or len(self.dest) != m or len(self.base) != m:
            raise ValueError(f"state {self.t}: pos, tau, dest and base must have one entry per taxi")
        if len(self.home) not in (0, m):
            raise ValueError(f"state {self.t}: home must be empty or have one entry per taxi")
        if not (len(self.new_pickup) == len(self.new_dropoff) == len(self.new_entry) == k):
            raise ValueError(f"state {self.t}: new_index, new_pickup, new_dropoff and new_entry differ in length")


@dataclass(frozen=True)
class Snapshot(Message):
    """A full state with the current hour's forecast (empty before the run's first minute): how an agent joins or rejoins mid-run."""

    kind: ClassVar[str] = "snapshot"
    state: bytes
    forecast: bytes


@dataclass(frozen=True)
class Turn(Message):
    """Agent ``agent`` plans minute ``t`` now, with the committed controls of the predecessors it depends on.

    ``deps`` are those predecessors (ascending agent indices, all free and
    before ``agent``) and ``controls`` their committed controls, in the same
    order: the agent plays every other predecessor at the state's ``base``
    control, which cannot change its costs (:mod:`agents.waves`).  Carrying
    them here spares the agent a subscription to every commitment.

    ``epoch`` is the run epoch of the coordinator that sent it: a coordinator
    that takes a run over (``--takeover``) starts a higher one, and an agent
    drops whatever comes from a lower epoch than the highest it has seen, so
    a fenced coordinator can no longer steer the fleet.
    """

    kind: ClassVar[str] = "turn"
    arrays: ClassVar[dict[str, str]] = {"deps": I32, "controls": I32}
    t: int
    agent: int
    deps: np.ndarray
    controls: np.ndarray
    epoch: int

    def __post_init__(self) -> None:
        if len(self.deps) != len(self.controls):
            raise ValueError(f"turn {self.t}: deps and controls differ in length")


@dataclass(frozen=True)
class Control(Message):
    """An agent's control for minute ``t``: proposed by the agent, or committed by the coordinator.

    ``by`` is ``agent`` for a planned control and ``base`` when the
    coordinator committed the base policy's control for a silent agent.
    ``epoch`` is the run epoch of the turn it answers (or of the committing
    coordinator): a coordinator takes only controls of its own epoch.
    """

    kind: ClassVar[str] = "control"
    t: int
    agent: int
    control: int
    epoch: int
    by: str = "agent"
    plan_s: float = 0.0
    #: The sender's peak resident memory, so the coordinator can report what an agent costs.
    rss_mb: float = 0.0


@dataclass(frozen=True)
class Ack(Message):
    """Agent ``agent`` holds the state of minute ``t``: a suspect agent is waited for again once it acks the current minute."""

    kind: ClassVar[str] = "ack"
    t: int
    agent: int


@dataclass(frozen=True)
class Stop(Message):
    """The run is over: ``reason`` is ``done`` after the last minute, anything else says why it ended at minute ``t``.

    An agent obeys only the stop of the run epoch it follows (:attr:`Turn.epoch`).
    """

    kind: ClassVar[str] = "stop"
    t: int
    epoch: int
    reason: str = field(default="done")
