"""Faults over a real secured router on loopback: killed and hung agents, a restarted router, a stopped or resumed coordinator.

Each run is a few taxis on the synthetic city with few samples; the router,
the sessions and the processes are real.  Agents run as plain processes
(``AGENT``) so that the test can kill or stop exactly one of them; the test
watches turns with a taxi's own credentials, as that taxi would.
"""

from __future__ import annotations

import json
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

from bus.certs import make_certs
from bus.router import free_tcp_port, wait_for_tcp
from bus.session import Inbox
from city.errors import DataError
from coordinator.faults import PartitionError

CLI = [sys.executable, "-m", "coordinator.cli"]
pytestmark = pytest.mark.usefixtures("compiled_kernels")

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
        return _next_turn(self.turns, answered + 1)

    def close(self) -> None:
        self._ctx.__exit__(None, None, None)


@pytest.fixture
def bus(tmp_path: Path) -> Iterator[Bus]:
    b = Bus(tmp_path, 3)
    try:
        yield b
    finally:
        b.close()


def _coordinator(bus: Bus, run: str, *extra: str, minutes: int, deadline: float, minute_s: float) -> Logged:
    return Logged([*CLI, "coordinator", *bus.flags, "--run", run, "--taxis", "3", "--minutes", str(minutes),
                   "--forecast", "true-rate", "--samples", "40", "--deadline", str(deadline), "--minute-seconds", str(minute_s),
                   "--join-timeout", "300", *extra])


def _next_turn(turns: queue.SimpleQueue, at_least: int, timeout: float = 120) -> int:
    deadline = time.monotonic() + timeout
    while True:
        t = turns.get(timeout=max(0.1, deadline - time.monotonic()))
        if t >= at_least:
            return t


def test_router_restart_and_coordinator_resume_keep_the_uninterrupted_decisions(bus: Bus, tmp_path: Path) -> None:
    """The router is killed and restarted mid-run (a partition: the clock pauses), then the coordinator is
    SIGKILLed and resumed from its checkpoint: the decisions are those of the in-process run."""
    from coordinator.fleet import in_process, resumed_config

    run, run_dir, minutes = "faults", tmp_path / "run", 14
    coord = _coordinator(bus, run, "--run-dir", str(run_dir), minutes=minutes, deadline=60, minute_s=0.4)
    agents = [bus.agent(i, run, grace=90) for i in range(3)]
    resumed = None
    try:
        coord.wait_for(f"minute 3/{minutes}")
        bus.kill()
        coord.wait_for("partition: 3 of 3 agents' tokens are gone")
        time.sleep(1.0)
        bus.start()
        coord.wait_for("partition healed")
        coord.wait_for(f"minute 8/{minutes}")
        coord.proc.send_signal(signal.SIGKILL)
        coord.finish(30)
        for a in agents:
            a.wait_for("the coordinator's token is gone")
        out = tmp_path / "resumed.json"
        resumed = Logged([*CLI, "coordinator", *bus.flags, "--resume", str(run_dir), "--json", str(out)])
        assert resumed.finish(180) == 0, resumed.text
        assert [a.finish(60) for a in agents] == [0, 0, 0], "\n".join(a.text for a in agents)
    finally:
        for p in (coord, resumed, *agents):
            if p is not None:
                p.kill()
    result = json.loads(out.read_text())
    assert "resuming run 'faults' at minute" in resumed.text and result["resumed_at_minute"] >= 8
    assert all("the coordinator is back" in a.text for a in agents)
    assert result["fallbacks"] == 0 and len(result["controls"]) == minutes
    assert len(result["waves"]) == len(result["critical_path"]) == minutes  # the waves of the minutes before the resume, restored
    assert result["traffic"]["received_messages"] >= sum(result["planned_per_agent"])  # and the traffic counted before it
    assert "silent for" not in coord.text + resumed.text and "gone; base control used" not in coord.text
    ref = in_process(resumed_config(str(run_dir)))
    assert result["decisions_sha256"] == ref["decisions_sha256"]
    assert result["total_cost"] == ref["total_cost"]


def test_the_router_drill_of_bench_fleet_reports_the_pause_and_keeps_the_decisions(tmp_path: Path) -> None:
    """`surge bench fleet --restart-router-after`: the launcher kills its own router mid-run and starts it again; the
    coordinator records the partition it paused for, and the run still makes the in-process decisions."""
    out = tmp_path / "drill.json"
    run = subprocess.run([*CLI, "bench", "fleet", "--taxis", "4", "--minutes", "8", "--samples", "20", "--horizon", "4",
                          "--forecast", "true-rate", "--hosts", "2", "--minute-seconds", "1", "--restart-router-after", "2",
                          "--json", str(out)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    rep = json.loads(out.read_text())
    drill = rep["router_restart"]
    assert rep["same_decisions"] and rep["fallbacks"] == 0
    assert drill["killed_at"] < drill["restarted_at"] and drill["router_away_s"] >= 1.0
    assert len(drill["partitions"]) == 1 and drill["partitions"][0]["tokens_gone"] == 4
    assert drill["partitions"][0]["minute"] >= 2 and 0 < drill["paused_s"] <= drill["hit_minute_seconds"][0]
    assert "router killed after minute 2" in run.stdout and "the clock paused" in run.stdout


def test_bench_fleet_refuses_a_router_drill_outside_the_run() -> None:
    run = subprocess.run([*CLI, "bench", "fleet", "--taxis", "2", "--minutes", "3", "--restart-router-after", "3"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode != 0 and "--restart-router-after 3: the run has minutes 1 to 2" in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1


def test_an_interrupted_fleet_resumes_from_its_checkpoint(tmp_path: Path) -> None:
    """`surge fleet` SIGTERMed mid-run, then `surge fleet --resume`: a new router and new agents finish the same run."""
    run_dir, out, minutes = tmp_path / "run", tmp_path / "resumed.json", 12
    first = Logged([*CLI, "fleet", "--taxis", "2", "--minutes", str(minutes), "--forecast", "true-rate", "--samples", "50",
                    "--minute-seconds", "0.3", "--run-dir", str(run_dir)])
    try:
        assert f"--resume {run_dir}` continues the run" in first.wait_for("checkpointing each minute to")
        first.wait_for(f"minute 5/{minutes}")
        first.proc.send_signal(signal.SIGTERM)
        assert first.finish(60) == 143, first.text
    finally:
        first.kill()
    proc = subprocess.run([*CLI, "fleet", "--resume", str(run_dir), "--check", "--json", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "decisions identical" in proc.stdout, proc.stdout
    result = json.loads(out.read_text())
    assert 5 <= result["resumed_at_minute"] < minutes and len(result["controls"]) == minutes
    assert result["same_decisions"] and result["fallbacks"] == 0


def test_a_killed_agent_rejoins_and_a_hung_agent_costs_one_deadline(bus: Bus, tmp_path: Path) -> None:
    """Agent 1 is SIGKILLed mid-turn and restarted; then agent 2 is SIGSTOPped mid-turn and SIGCONTed."""
    run, minutes, deadline, out = "agents", 40, 1.5, tmp_path / "result.json"
    coord = _coordinator(bus, run, "--json", str(out), minutes=minutes, deadline=deadline, minute_s=0.4)
    agents = {i: bus.agent(i, run, grace=60) for i in range(3)}
    watch = {i: bus.watch(i, run) for i in (1, 2)}
    try:
        coord.wait_for("all 3 agents joined")
        t_kill = _next_turn(watch[1].turns, watch[1].stop_after_an_answer(agents[1], 2) + 1)
        agents[1].proc.send_signal(signal.SIGKILL)  # at once, well within its turn's deadline
        agents[1].finish(30)
        coord.wait_for("agent 1 left")
        agents[1] = bus.agent(1, run, grace=60)
        coord.wait_for("agent 1 is back")
        t_stop = watch[2].stop_with_a_turn_outstanding(agents[2], t_kill)
        coord.wait_for("agent 2 silent for", timeout=60)
        time.sleep(2 * deadline)  # minutes go by with agent 2 suspect
        agents[2].proc.send_signal(signal.SIGCONT)
        acked = int(coord.wait_for("agent 2 acknowledged minute").split("acknowledged minute ")[1].split(";")[0])
        assert coord.finish(180) == 0, coord.text
        assert [agents[i].finish(60) for i in range(3)] == [0, 0, 0], "\n".join(a.text for a in agents.values())
    finally:
        for w in watch.values():
            w.close()
        for p in (coord, *agents.values()):
            p.kill()
    result = json.loads(out.read_text())
    fallen = {a: [t for t, b in result["fallback_turns"] if b == a] for a in range(3)}
    assert fallen[0] == [] and result["fallbacks_per_agent"] == [len(fallen[a]) for a in range(3)]
    assert fallen[1], "the killed agent's turns were not counted as fallbacks"
    assert "joined run 'agents'" in agents[1].text, "the restarted agent did not rejoin"
    assert "the coordinator's token is gone" not in agents[0].text  # its token goes with the stop at a normal end
    assert "agent 1 silent for" not in coord.text  # it took its snapshot before its token: no turn of its waited out a deadline
    assert coord.text.count("agent 2 silent for") == 1  # suspect after one deadline: no further wait, the run keeps its pace
    assert fallen[2] and min(fallen[2]) >= t_stop and max(fallen[2]) <= acked
    assert max(max(fallen[1]), acked) < minutes - 5, "too few minutes after the faults to show the agents recovered"
    assert len(result["controls"]) == minutes


def test_an_agent_back_before_its_departure_settles_gets_the_base_control_at_once(bus: Bus) -> None:
    """Agent 1 is stopped with a turn outstanding, then killed while the coordinator is stopped too, and a process
    declares its token at once: the coordinator sees it leave and come back in one burst.  The turn went with the
    process that left, so it is the base control now, not a wait for the deadline (the race a fast restart hit)."""
    run = "back"
    coord = _coordinator(bus, run, minutes=60, deadline=60, minute_s=0.4)
    agents = [bus.agent(i, run, grace=60) for i in range(3)]
    watch = bus.watch(1, run)
    try:
        coord.wait_for("all 3 agents joined")
        t = watch.stop_with_a_turn_outstanding(agents[1], 2)
        coord.proc.send_signal(signal.SIGSTOP)
        agents[1].proc.send_signal(signal.SIGKILL)
        agents[1].finish(30)
        token = watch.session.liveliness().declare_token(watch.keys.alive(1))  # a process back in its place at once
        time.sleep(1.0)  # the router holds the departure and the return for the stopped coordinator
        coord.proc.send_signal(signal.SIGCONT)
        gone = coord.wait_for(f"minute {t}: agent 1 gone; base control used", timeout=30)
        token.undeclare()
    finally:
        watch.close()
        for p in (coord, *agents):
            p.kill()
    lines = coord.lines
    assert lines.index(coord.wait_for("agent 1 left")) < lines.index(coord.wait_for("agent 1 is back")) < lines.index(gone)
    assert "silent for" not in coord.text


def test_a_stopped_coordinator_stops_its_agents_within_the_grace_period(bus: Bus) -> None:
    """SIGTERM: the coordinator publishes stop and every agent leaves at once; SIGKILL: they leave after the grace period."""
    grace = 4.0
    for sig, run in ((signal.SIGTERM, "term"), (signal.SIGKILL, "kill")):
        coord = _coordinator(bus, run, minutes=60, deadline=30, minute_s=0.5)
        agents = [bus.agent(i, run, grace=grace) for i in range(3)]
        try:
            coord.wait_for("minute 2/60")
            coord.proc.send_signal(sig)
            t0 = time.monotonic()
            codes = [a.finish(grace + 20) for a in agents]
            took = time.monotonic() - t0
            rc = coord.finish(30)
        finally:
            for p in (coord, *agents):
                p.kill()
        if sig == signal.SIGTERM:
            assert rc == 143 and "published stop at minute" in coord.text
            assert codes == [0, 0, 0] and took < grace
            assert all("the coordinator ended the run at minute" in a.text for a in agents)
            assert not any("the coordinator's token is gone" in a.text for a in agents)
        else:
            assert codes == [2, 2, 2] and grace < took < grace + 15
            assert all(f"has been gone for more than {grace:g} s (the grace period); leaving" in a.text for a in agents)


# ------------------------------------------------------------------ without a bus
def test_a_checkpoint_restores_the_run_and_a_bad_one_is_one_line(tmp_path: Path) -> None:
    from dataclasses import asdict

    from coordinator import checkpoint
    from coordinator.run_config import FleetConfig
    from coordinator.runtime import Coordinator

    cfg = FleetConfig(run="ck", taxis=3, minutes=5, options={"forecast": "true-rate", "samples": 4}, partition_timeout_s=0.3)
    coord = Coordinator(cfg, progress=False)
    sim, tally = coord.sim, coord.tally
    for t in range(3):
        u = sim.busy_controls()
        u[sim.state.tau == 0] = sim.state.pos[sim.state.tau == 0]
        tally.controls[t] = u
        tally.costs.append(sim.step(u))
    tally.fallen.append([1, 2])
    tally.waves.extend([[{"seconds": 0.5, "agents": [0, 2], "plan_s": [0.1, None]}]] * 3)
    tally.traffic.sent(b"state")
    checkpoint.save(tmp_path, asdict(cfg), sim, tally)
    back = Coordinator(cfg, progress=False, run_dir=tmp_path, resume=True)
    assert back.sim.state.t == 3 and np.array_equal(back.sim.state.pos, sim.state.pos)
    assert np.array_equal(back.sim.state.picked_at, sim.state.picked_at)
    assert np.array_equal(back.tally.controls, tally.controls) and back.tally.costs == tally.costs and back.tally.fallen == [[1, 2]]
    assert back.tally.waves == tally.waves and back.tally.traffic == tally.traffic
    doc = json.loads((tmp_path / checkpoint.CHECKPOINT).read_text())
    doc["sim"]["picked_at"] = doc["sim"]["picked_at"][:-1]
    (tmp_path / checkpoint.CHECKPOINT).write_text(json.dumps(doc))
    with pytest.raises(DataError, match=r"checkpoint.json: field 'sim' holds \d+ requests, the run's instance has \d+"):
        checkpoint.restore(tmp_path, back.sim, cfg.minutes)
    (tmp_path / checkpoint.CHECKPOINT).write_text("{")
    with pytest.raises(DataError, match="checkpoint.json: not readable as JSON"):
        checkpoint.restore(tmp_path, back.sim, cfg.minutes)
    with pytest.raises(DataError, match="nothing to resume"):
        checkpoint.restore(tmp_path / "none", back.sim, cfg.minutes)
    assert back.sim.state.t == 3  # a refused checkpoint leaves the simulator as it was
    from bus.wire import Ack

    back.obs = back.sim.observe()
    back.health.missed({1}, 3, 1.0)
    for key, ack in ((back.keys.ack(2), Ack(t=3, agent=1)), (back.keys.ack(1), Ack(t=99, agent=1))):
        back._handle(("ack", key, ack.encode()))  # another agent's key; a minute outside the episode
    assert 1 in back.health.suspect and len(back.rejected.counts) == 2
    back._handle(("ack", back.keys.ack(1), Ack(t=3, agent=1).encode()))
    assert 1 not in back.health.suspect
    now = time.monotonic()
    back.health.departed, back.health.last_departure = {0: now - 0.6, 1: now - 0.6, 2: now - 0.6}, now - 0.6
    with pytest.raises(PartitionError, match=r"^run 'ck': partition at minute 3: 0 of 3 agents returned within 0.3 s; the run ends$"):
        back._partition(Inbox(), 3)
    back.health.departed = {a: when - 60 for a, when in back.health.departed.items()}
    back.health.alive = {2}
    assert back._partition(Inbox(), 4) is False  # worn down one agent at a time long ago: the clock goes on without them


# ------------------------------------------------------------ one coordinator per run
def test_a_second_coordinator_is_refused_and_a_run_directory_is_locked(bus: Bus) -> None:
    """While a coordinator of run 'solo' is alive, a second one is refused, naming the run and since when; its default run
    directory is its own; and a coordinator of another run on the first one's run directory is refused by the lock."""
    first = _coordinator(bus, "solo", minutes=5, deadline=30, minute_s=0)
    flags = [*bus.flags, "--taxis", "3", "--minutes", "5", "--forecast", "true-rate", "--samples", "40"]
    try:
        first.wait_for("this coordinator is run epoch")
        run_dir = first.wait_for("checkpointing each minute to ").split(" to ", 1)[1].split(";")[0]
        assert Path(run_dir).parent.name == "runs" and Path(run_dir).name.startswith("solo-")
        second = subprocess.run([*CLI, "coordinator", "--run", "solo", *flags], capture_output=True, text=True, timeout=300)
        errors = [line for line in second.stderr.splitlines() if "error" in line]
        assert second.returncode == 2 and len(errors) == 1, second.stderr
        assert "run 'solo' has a live coordinator (run epoch " in errors[0] and ", since 20" in errors[0]
        assert "refusing to start a second one" in errors[0] and "--takeover" in errors[0]
        assert f"checkpointing each minute to {run_dir};" not in second.stderr  # a run directory of its own
        third = subprocess.run([*CLI, "coordinator", "--run", "other", "--run-dir", run_dir, *flags], capture_output=True, text=True,
                               timeout=300)
        errors = [line for line in third.stderr.splitlines() if "error" in line]
        assert third.returncode == 2 and len(errors) == 1, third.stderr
        assert f"run directory {run_dir} is locked by the coordinator of run 'solo' (process {first.proc.pid} on " in errors[0]
        assert first.proc.poll() is None
    finally:
        first.kill()


def test_takeover_fences_the_first_coordinator_and_keeps_the_uninterrupted_decisions(bus: Bus, tmp_path: Path) -> None:
    """A second coordinator resumes a live run with --takeover: the first stops without another checkpoint or stop, the
    agents follow the new run epoch, and the decisions are those of the in-process run."""
    from coordinator.fleet import in_process, resumed_config

    run, run_dir, minutes, out = "fence", tmp_path / "run", 12, tmp_path / "second.json"
    first = _coordinator(bus, run, "--run-dir", str(run_dir), minutes=minutes, deadline=60, minute_s=3.0)  # room for a second to start
    agents = [bus.agent(i, run, grace=90) for i in range(3)]
    second = None
    try:
        first.wait_for(f"minute 1/{minutes}")
        second = Logged([*CLI, "coordinator", *bus.flags, "--resume", str(run_dir), "--takeover", "--json", str(out)])
        assert first.finish(180) == 2, first.text + "\n---\n" + second.text
        assert second.finish(300) == 0, second.text
        assert [a.finish(60) for a in agents] == [0, 0, 0], "\n".join(a.text for a in agents)
    finally:
        for p in (first, second, *agents):
            if p is not None:
                p.kill()
    assert "taking run 'fence' over from the coordinator of run epoch" in second.text
    assert "was taken over by the coordinator of run epoch" in first.text and "published stop" not in first.text
    assert all("took the run over from epoch" in a.text for a in agents)
    result = json.loads(out.read_text())
    assert 1 <= result["resumed_at_minute"] < minutes and len(result["controls"]) == minutes and result["fallbacks"] == 0
    ref = in_process(resumed_config(str(run_dir)))
    assert result["decisions_sha256"] == ref["decisions_sha256"] and result["total_cost"] == ref["total_cost"]
