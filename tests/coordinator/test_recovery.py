"""A run outlives its coordinator: checkpoints and resume, one coordinator per run, and a takeover.

Over a real secured router on loopback where a bus is needed (``fault_rig``);
the checkpoint's own checks run without one.
"""

from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from bus.session import Inbox
from city.errors import DataError
from coordinator.faults import PartitionError
from tests.coordinator.fault_rig import CLI, Bus, Logged, coordinator, kill_all

pytestmark = pytest.mark.usefixtures("compiled_kernels")


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


def test_a_second_coordinator_is_refused_and_a_run_directory_is_locked(bus: Bus) -> None:
    """While a coordinator of run 'solo' is alive, a second one is refused, naming the run and since when; its default run
    directory is its own; and a coordinator of another run on the first one's run directory is refused by the lock."""
    first = coordinator(bus, "solo", minutes=5, deadline=30, minute_s=0)
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
    first = coordinator(bus, run, "--run-dir", str(run_dir), minutes=minutes, deadline=60, minute_s=3.0)  # room for a second to start
    agents = [bus.agent(i, run, grace=90) for i in range(3)]
    second = None
    try:
        first.wait_for(f"minute 1/{minutes}")
        second = Logged([*CLI, "coordinator", *bus.flags, "--resume", str(run_dir), "--takeover", "--json", str(out)])
        assert first.finish(180) == 2, first.text + "\n---\n" + second.text
        assert second.finish(300) == 0, second.text
        assert [a.finish(60) for a in agents] == [0, 0, 0], "\n".join(a.text for a in agents)
    finally:
        kill_all(first, second, *agents)
    assert "taking run 'fence' over from the coordinator of run epoch" in second.text
    assert "was taken over by the coordinator of run epoch" in first.text and "published stop" not in first.text
    assert all("took the run over from epoch" in a.text for a in agents)
    result = json.loads(out.read_text())
    assert 1 <= result["resumed_at_minute"] < minutes and len(result["controls"]) == minutes and result["fallbacks"] == 0
    ref = in_process(resumed_config(str(run_dir)))
    assert result["decisions_sha256"] == ref["decisions_sha256"] and result["total_cost"] == ref["total_cost"]
