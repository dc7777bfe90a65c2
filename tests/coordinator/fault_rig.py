"""A secured router on loopback that a test can kill and restart, taxi processes it can kill or stop, and a taxi's view of its turns.

Shared by the fault tests (``test_faults.py``) and the recovery tests
(``test_recovery.py``); the ``bus`` fixture is in ``conftest.py``.
"""

from __future__ import annotations

import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from bus.certs import make_certs
from bus.router import free_tcp_port, wait_for_tcp

CLI = [sys.executable, "-m", "coordinator.cli"]
AGENT = """
import sys
from agents.taxi import AgentConfig, agent_main
from bus.session import SessionArgs
i, run, endpoint, certs, grace = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4], float(sys.argv[5])
bus = SessionArgs(mode="client", connect=[endpoint], certs=certs, identity=f"taxi-{i}")
sys.exit(agent_main(AgentConfig(index=i, run=run, bus=bus, grace_s=grace)))
"""


class Logged:
    """A process whose stderr lines are collected as they come, so a test can wait for one."""

    def __init__(self, argv: list[str]) -> None:
        self.proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stderr:  # type: ignore[union-attr]
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, text: str, timeout: float = 120) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in list(self.lines):
                if text in line:
                    return line
            if self.proc.poll() is not None:
                self._reader.join(5)
                if not any(text in line for line in self.lines):
                    break
            time.sleep(0.05)
        raise AssertionError(f"no line with {text!r} within {timeout} s; got:\n" + "\n".join(self.lines[-30:]))

    def finish(self, timeout: float = 120) -> int:
        rc = self.proc.wait(timeout)
        self._reader.join(5)
        return rc

    @property
    def text(self) -> str:
        return "\n".join(self.lines)

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)


class Bus:
    """A secured router on a fixed port that the test can kill and start again."""

    def __init__(self, tmp: Path, taxis: int) -> None:
        self.certs = str(tmp / "certs")
        make_certs(self.certs, taxis)
        self.port = free_tcp_port()
        self.endpoint = f"tls/127.0.0.1:{self.port}"
        self.router: subprocess.Popen | None = None
        self.start()

    def start(self) -> None:
        self.router = subprocess.Popen([*CLI, "router", "--certs", self.certs, "--listen", self.endpoint], stderr=subprocess.DEVNULL)
        wait_for_tcp("127.0.0.1", self.port, 30)

    def kill(self) -> None:
        assert self.router is not None
        self.router.kill()
        self.router.wait(10)

    @property
    def flags(self) -> list[str]:
        return ["--connect", self.endpoint, "--certs", self.certs]

    def agent(self, i: int, run: str, grace: float) -> Logged:
        return Logged([sys.executable, "-c", AGENT, str(i), run, self.endpoint, self.certs, str(grace)])

    def watch(self, agent: int, run: str) -> Watch:
        return Watch(self, agent, run)

    def close(self) -> None:
        if self.router is not None and self.router.poll() is None:
            self.router.terminate()
            self.router.wait(10)


class Watch:
    """A session as taxi ``agent``, as that taxi would hold one: its turns' minutes and its committed controls, in queues.

    With it the test can stop the taxi's process with a turn provably
    outstanding (:meth:`stop_with_a_turn_outstanding`), however fast it plans.
    """

    def __init__(self, bus: Bus, agent: int, run: str) -> None:
        from bus.keys import Keys
        from bus.session import SessionArgs, open_session
        from bus.wire import Control, Turn, decode

        self.keys = Keys(run)
        self.turns: queue.SimpleQueue = queue.SimpleQueue()
        self.committed: queue.SimpleQueue = queue.SimpleQueue()
        self._ctx = open_session(SessionArgs(mode="client", connect=[bus.endpoint], certs=bus.certs, identity=f"taxi-{agent}"))
        self.session = self._ctx.__enter__()
        self.session.declare_subscriber(self.keys.turn(agent), lambda s: self.turns.put(decode(s.payload.to_bytes(), Turn).t))
        self.session.declare_subscriber(self.keys.committed(agent), lambda s: self.committed.put(decode(s.payload.to_bytes(), Control)))

    def stop_after_an_answer(self, agent: Logged, after: int) -> int:
        """SIGSTOP ``agent`` once it has answered a turn of minute ``after`` or later; the latest minute it answered, as far as seen."""
        answered = -1
        while answered < after or not self.committed.empty():
            if (c := self.committed.get(timeout=120)).by == "agent":
                answered = max(answered, c.t)
        agent.proc.send_signal(signal.SIGSTOP)
        return answered

    def stop_with_a_turn_outstanding(self, agent: Logged, after: int) -> int:
        """:meth:`stop_after_an_answer`, then the minute of its first turn left unanswered, exactly."""
        answered = self.stop_after_an_answer(agent, after)
        time.sleep(0.5)  # a control it sent before it stopped is committed by now
        while not self.committed.empty():
            if (c := self.committed.get()).by == "agent":
                answered = max(answered, c.t)
        return next_turn(self.turns, answered + 1)

    def close(self) -> None:
        self._ctx.__exit__(None, None, None)


def coordinator(bus: Bus, run: str, *extra: str, minutes: int, deadline: float, minute_s: float) -> Logged:
    return Logged([*CLI, "coordinator", *bus.flags, "--run", run, "--taxis", "3", "--minutes", str(minutes),
                   "--forecast", "true-rate", "--samples", "40", "--deadline", str(deadline), "--minute-seconds", str(minute_s),
                   "--join-timeout", "300", *extra])


def next_turn(turns: queue.SimpleQueue, at_least: int, timeout: float = 120) -> int:
    deadline = time.monotonic() + timeout
    while True:
        t = turns.get(timeout=max(0.1, deadline - time.monotonic()))
        if t >= at_least:
            return t


def kill_all(*procs: Logged | None) -> None:
    """Kill every process still running (a test's ``finally``); ``None`` stands for one never started."""
    for p in procs:
        if p is not None:
            p.kill()
