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

import argparse
import dataclasses
import json
import queue
import sys
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import zenoh

from bus.access import access_control
from bus.certs import check_credentials, fleet_size, identity
from bus.wire import ENCODING
from city.errors import ConfigError

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


def add_session_args(p: argparse.ArgumentParser, mode: str = "client") -> None:
    """``--mode``, ``--connect``, ``--listen``, ``--config`` and ``--multicast``, as zenoh's examples take them."""
    p.add_argument("--mode", choices=MODES, default=mode, help=f"zenoh session mode (default: {mode})")
    p.add_argument("--connect", "-e", action="append", default=[], metavar="ENDPOINT", help="endpoint to connect to, e.g. tcp/10.0.0.1:7447")
    p.add_argument("--listen", "-l", action="append", default=[], metavar="ENDPOINT", help="endpoint to listen on")
    p.add_argument("--config", default=None, help="zenoh JSON5 config file (the flags above override it)")
    p.add_argument("--multicast", action="store_true", help="allow multicast scouting (off: endpoints are explicit)")
    add_security_args(p)


def add_security_args(p: argparse.ArgumentParser) -> None:
    """``--certs DIR`` (mutual TLS and access control, the default way to run) and ``--insecure``."""
    p.add_argument("--certs", default=None, metavar="DIR",
                   help="the fleet's credentials (made by `surge certs`): mutual TLS, and access control at the router")
    p.add_argument("--insecure", action="store_true",
                   help="run the bus without TLS or access control (anyone who reaches the router can steer the fleet)")


#: Where a client looks for its router, and where a router listens, unless told otherwise.
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
#: The same on a secured bus.
DEFAULT_TLS_ENDPOINT = "tls/127.0.0.1:7447"
INSECURE_WARNING = "surge: warning: --insecure: the bus runs without TLS or access control; anyone who reaches it can steer the fleet"


def warn_insecure() -> None:
    """The one line an insecure run prints."""
    print(INSECURE_WARNING, file=sys.stderr, flush=True)


def security(args: argparse.Namespace) -> str | None:
    """The credentials directory of ``--certs``, or ``None`` under ``--insecure`` (after its warning); neither is an error."""
    certs, insecure = getattr(args, "certs", None), getattr(args, "insecure", False)
    if certs is not None and insecure:
        raise ConfigError("--certs and --insecure: choose one")
    if certs is None and not insecure:
        raise ConfigError("the bus runs with mutual TLS and access control: pass --certs DIR "
                          "(make it with `surge certs --out DIR --taxis N`), or --insecure to run without")
    if insecure:
        warn_insecure()
    return certs


def session_args(args: argparse.Namespace, identity: str | None = None, run: str | None = None) -> SessionArgs:
    """Session settings from the shared flags, presenting ``identity``'s credentials (a router may scope its rules to ``run``).

    A client with no ``--connect`` (or a router with no ``--listen``) uses the default endpoint.
    """
    SessionArgs(mode=args.mode, connect=list(args.connect), listen=list(args.listen))  # the flags' own errors first
    if args.config is not None and not Path(args.config).is_file():
        raise ConfigError(f"zenoh config {args.config}: no such file")
    certs = security(args)
    default = DEFAULT_ENDPOINT if certs is None else DEFAULT_TLS_ENDPOINT
    connect, listen = list(args.connect), list(args.listen)
    if args.mode == "client" and not connect and args.config is None:
        connect = [default]
    if args.mode == "router" and not listen and args.config is None:
        listen = [default]
    out = SessionArgs(mode=args.mode, connect=connect, listen=listen, config=args.config, multicast=args.multicast,
                      certs=certs, identity=identity if certs is not None else None, run=run)
    if certs is not None and identity is not None:
        out.overrides()  # a missing credential file is one line now, not a failure in a spawned process
    return out


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
