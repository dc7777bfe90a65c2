"""Zenoh sessions: shared command-line arguments, config building and the inbox.

Sessions are opened only inside the process that uses them (never before a
``fork``) and always as context managers.  Multicast scouting is off unless
asked for: endpoints are explicit, so runs on a shared network do not find
each other by accident.  Callbacks never block and never call zenoh: they put
what arrived in an :class:`Inbox`, which the owning thread reads.

The bus is secured unless the user opts out: with a credentials directory
(:mod:`bus.certs`) every link is TLS with certificates on both ends, and a
router enforces the access rules of :mod:`bus.access`.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import queue
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import zenoh

from bus.access import access_control
from bus.certs import check_credentials, fleet_size, identity
from bus.wire import ENCODING
from city.errors import ConfigError

_logger = logging.getLogger(__name__)

MODES = ("peer", "client", "router")


@dataclass(frozen=True)
class SessionArgs:
    """How to reach the bus, as in zenoh's own examples."""

    mode: str = "peer"
    connect: list[str] = field(default_factory=list)
    listen: list[str] = field(default_factory=list)
    config: str | None = None
    multicast: bool = False
    #: The fleet's credentials directory (``surge certs``); ``None`` runs without TLS or access control.
    certs: str | None = None
    #: Whose credentials this session presents: ``router``, ``coordinator``, ``predictor`` or ``taxi-<i>``.
    identity: str | None = None
    #: Routers only: the run whose keys the access rules cover (``None``: every run).
    run: str | None = None

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ConfigError(f"zenoh mode {self.mode!r}; choose from {', '.join(MODES)}")
        for ep in [*self.connect, *self.listen]:
            proto, sep, addr = ep.partition("/")
            if not sep or not proto or not addr:
                raise ConfigError(f"zenoh endpoint {ep!r}: expected PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447")
            if self.certs is not None and proto != "tls":
                raise ConfigError(f"zenoh endpoint {ep!r}: a secured bus (--certs) runs over tls/ endpoints, e.g. tls/127.0.0.1:7447")
        if self.certs is not None and self.mode == "peer":
            raise ConfigError("--certs: a secured bus has a router and clients; use --mode client (or router), not peer")

    def as_identity(self, name: str) -> SessionArgs:
        """The same settings presenting ``name``'s credentials (unchanged on an insecure bus)."""
        return self if self.certs is None else dataclasses.replace(self, identity=name)

    def overrides(self) -> dict[str, Any]:
        """The zenoh config entries these settings set, by config path; they go over ``config``'s file."""
        out: dict[str, Any] = {"mode": self.mode}
        if self.connect:
            out["connect/endpoints"] = list(self.connect)
        if self.listen:
            out["listen/endpoints"] = list(self.listen)
        out["scouting/multicast/enabled"] = self.multicast
        if self.certs is not None:
            if self.identity is None:
                raise ConfigError("a secured session needs an identity (router, coordinator, predictor or taxi-<i>)")
            ident = identity(self.certs, self.identity)
            check_credentials(ident)  # before connecting: an operator's one line, not zenoh's "unable to connect"
            tls: dict[str, Any] = {"root_ca_certificate": str(ident.ca), "enable_mtls": True}
            side = "listen" if self.mode == "router" else "connect"
            tls.update({f"{side}_certificate": str(ident.cert), f"{side}_private_key": str(ident.key)})
            out["transport/link/protocols"] = ["tls"]
            out["transport/link/tls"] = tls
            if self.mode == "router":
                out["access_control"] = access_control(fleet_size(self.certs), self.run)
        return out

    def zenoh_config(self) -> zenoh.Config:
        if self.config is not None:
            path = Path(self.config)
            if not path.is_file():
                raise ConfigError(f"zenoh config {path}: no such file")
            try:
                conf = zenoh.Config.from_file(str(path))
            except Exception as exc:  # zenoh raises its own ZError
                raise ConfigError(f"zenoh config {path}: {exc}") from None
        else:
            conf = zenoh.Config()
        for path, value in self.overrides().items():
            conf.insert_json5(path, json.dumps(value))
        return conf


#: Where a client looks for its router, and where a router listens, unless told otherwise.
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
#: The same on a secured bus.
DEFAULT_TLS_ENDPOINT = "tls/127.0.0.1:7447"
INSECURE_WARNING = "--insecure: the bus runs without TLS or access control; anyone who reaches it can steer the fleet"


def warn_insecure() -> None:
    """The one warning an insecure run gives."""
    _logger.warning("%s", INSECURE_WARNING)


@contextmanager
def open_session(args: SessionArgs) -> Iterator[zenoh.Session]:
    """A zenoh session, closed on exit; a failure to open is one line naming the endpoints."""
    conf = args.zenoh_config()
    try:
        session = zenoh.open(conf)
    except Exception as exc:
        where = ", ".join([f"connect {e}" for e in args.connect] + [f"listen {e}" for e in args.listen]
                          + ([f"config {args.config}"] if args.config else [])) or "zenoh's default endpoints"
        how = f" as {args.identity} with the credentials in {args.certs}" if args.certs is not None else ""
        raise ConfigError(f"cannot open a zenoh {args.mode} session ({where}){how}: {exc}") from None
    with session:
        yield session


class Inbox:
    """One queue for everything a process receives: ``(tag, key, payload)`` tuples, or ``(tag, key, query)``.

    Subscriber, queryable and liveliness callbacks only enqueue; the owning
    thread decodes, decides and replies.
    """

    def __init__(self) -> None:
        self._q: queue.SimpleQueue[tuple[str, str, Any]] = queue.SimpleQueue()

    def subscribe(self, session: zenoh.Session, key: str, tag: str) -> Any:
        return session.declare_subscriber(key, lambda s: self._q.put((tag, str(s.key_expr), s.payload.to_bytes())))

    def serve(self, session: zenoh.Session, key: str, tag: str) -> Any:
        return session.declare_queryable(key, lambda q: self._q.put((tag, str(q.key_expr), q)))

    def watch_liveliness(self, session: zenoh.Session, key: str, tag: str) -> Any:
        """Put ``(tag, key, True)`` when a token appears (including those already there) and ``False`` when it goes."""
        return session.liveliness().declare_subscriber(
            key, lambda s: self._q.put((tag, str(s.key_expr), s.kind == zenoh.SampleKind.PUT)), history=True
        )

    def put(self, tag: str, key: str, payload: Any) -> None:
        """Hand in an item as a callback would."""
        self._q.put((tag, key, payload))

    def get(self, timeout: float | None) -> tuple[str, str, Any] | None:
        """The next item, or ``None`` after ``timeout`` seconds."""
        try:
            return self._q.get(timeout=timeout)
        except queue.Empty:
            return None


def publisher(session: zenoh.Session, key: str) -> Any:
    """A publisher for turn, clock and control traffic: reliable, blocking rather than dropping, msgpack-encoded."""
    return session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE,
                                     encoding=ENCODING)
