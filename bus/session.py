"""Zenoh sessions: shared command-line arguments, config building and the inbox.

Sessions are opened only inside the process that uses them (never before a
``fork``) and always as context managers.  Multicast scouting is off unless
asked for: endpoints are explicit, so runs on a shared network do not find
each other by accident.  Callbacks never block and never call zenoh: they put
what arrived in an :class:`Inbox`, which the owning thread reads.
"""

from __future__ import annotations

import argparse
import json
import queue
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import zenoh

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

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ConfigError(f"zenoh mode {self.mode!r}; choose from {', '.join(MODES)}")
        for ep in [*self.connect, *self.listen]:
            proto, sep, addr = ep.partition("/")
            if not sep or not proto or not addr:
                raise ConfigError(f"zenoh endpoint {ep!r}: expected PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447")

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
        conf.insert_json5("mode", json.dumps(self.mode))
        if self.connect:
            conf.insert_json5("connect/endpoints", json.dumps(self.connect))
        if self.listen:
            conf.insert_json5("listen/endpoints", json.dumps(self.listen))
        conf.insert_json5("scouting/multicast/enabled", json.dumps(self.multicast))
        return conf


def add_session_args(p: argparse.ArgumentParser, mode: str = "client") -> None:
    """``--mode``, ``--connect``, ``--listen``, ``--config`` and ``--multicast``, as zenoh's examples take them."""
    p.add_argument("--mode", choices=MODES, default=mode, help=f"zenoh session mode (default: {mode})")
    p.add_argument("--connect", "-e", action="append", default=[], metavar="ENDPOINT", help="endpoint to connect to, e.g. tcp/10.0.0.1:7447")
    p.add_argument("--listen", "-l", action="append", default=[], metavar="ENDPOINT", help="endpoint to listen on")
    p.add_argument("--config", default=None, help="zenoh JSON5 config file (the flags above override it)")
    p.add_argument("--multicast", action="store_true", help="allow multicast scouting (off: endpoints are explicit)")


#: Where a client looks for its router, and where a router listens, unless told otherwise.
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


def session_args(args: argparse.Namespace) -> SessionArgs:
    """Session settings from the shared flags; a client with no ``--connect`` (or a router with no ``--listen``) uses the default endpoint."""
    connect, listen = list(args.connect), list(args.listen)
    if args.mode == "client" and not connect and args.config is None:
        connect = [DEFAULT_ENDPOINT]
    if args.mode == "router" and not listen and args.config is None:
        listen = [DEFAULT_ENDPOINT]
    return SessionArgs(mode=args.mode, connect=connect, listen=listen, config=args.config, multicast=args.multicast)


@contextmanager
def open_session(args: SessionArgs) -> Iterator[zenoh.Session]:
    """A zenoh session, closed on exit; a failure to open is one line naming the endpoints."""
    conf = args.zenoh_config()
    try:
        session = zenoh.open(conf)
    except Exception as exc:
        where = ", ".join([f"connect {e}" for e in args.connect] + [f"listen {e}" for e in args.listen]
                          + ([f"config {args.config}"] if args.config else [])) or "zenoh's default endpoints"
        raise ConfigError(f"cannot open a zenoh {args.mode} session ({where}): {exc}") from None
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

    def get(self, timeout: float | None) -> tuple[str, str, Any] | None:
        """The next item, or ``None`` after ``timeout`` seconds."""
        try:
            return self._q.get(timeout=timeout)
        except queue.Empty:
            return None


def publisher(session: zenoh.Session, key: str) -> Any:
    """A publisher for turn, clock and control traffic: reliable, and blocking rather than dropping."""
    return session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE)
