"""A zenoh router as a process of its own, for runs without a ``zenohd`` at hand."""

from __future__ import annotations

import logging
import os
import signal
import socket
import sys
import threading
import time

import zenoh

from bus.certs import fleet_size
from bus.session import SessionArgs, open_session
from city.errors import ConfigError

_logger = logging.getLogger(__name__)


#: What the router logs unless ``RUST_LOG`` says otherwise: zenoh's warnings, among them each TLS handshake it
#: refuses with zenoh's reason (``invalid peer certificate: …``: expired, or ``BadSignature`` for another CA; zenoh
#: does not say who), and each admitted session whose certificate no access rule names (by its zenoh id).
ROUTER_LOG = "warn,zenoh::net::routing::interceptor::access_control=info"


def router_main(bus: SessionArgs, announce: bool = False) -> None:
    """Open a router session and hold it until SIGTERM or SIGINT; with ``announce``, say where it listens once it does.

    ``announce`` (``surge router``) also turns on the log of :data:`ROUTER_LOG`, on stderr.  A local fleet's own router
    stays quiet: its launcher probes the port with bare TCP connections, which zenoh would log as failed handshakes.
    """
    if bus.mode != "router":
        raise ConfigError(f"router_main needs mode 'router', got {bus.mode!r}")
    if announce:
        sys.stdout.flush()
        os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # zenoh logs to stdout: one stream for the router's whole log
        zenoh.init_log_from_env_or(ROUTER_LOG)
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    with open_session(bus):
        if announce:
            where = ", ".join(bus.listen) or f"the endpoints of {bus.config}"
            if bus.certs is not None:
                scope = f"run {bus.run!r}" if bus.run else "every run"
                how = (f"mutual TLS with the CA in {bus.certs}, access control for {fleet_size(bus.certs)} taxis "
                       f"of {scope} (default deny)")
            else:
                how = "INSECURE: no TLS, no access control"
            _logger.info("zenoh router listening on %s; %s; Ctrl-C stops it", where, how)
        while not stop.wait(0.5):  # a timed wait: zenoh's threads may take the signal, and only this thread runs its handler
            pass


def free_tcp_port() -> int:
    """A loopback TCP port that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_for_tcp(host: str, port: int, timeout: float) -> None:
    """Block until something listens on ``host:port``; raise :class:`ConfigError` after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            with socket.create_connection((host, port), timeout=0.5):
                return
        except OSError:
            if time.monotonic() > deadline:
                raise ConfigError(f"nothing listens on {host}:{port} after {timeout:.0f} s") from None
            time.sleep(0.1)
