"""Faults over a real secured router on loopback: killed and hung agents, a restarted router, a stopped coordinator.

Each run is a few taxis on the synthetic city with few samples; the router,
the sessions and the processes are real.  Agents run as plain processes
(``fault_rig.AGENT``) so that the test can kill or stop exactly one of them; the test
watches turns with a taxi's own credentials, as that taxi would.
"""

from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path

import pytest

from tests.coordinator.fault_rig import CLI, Bus, Logged, coordinator, kill_all, next_turn

pytestmark = pytest.mark.usefixtures("compiled_kernels")


def test_router_restart_and_coordinator_resume_keep_the_uninterrupted_decisions(bus: Bus, tmp_path: Path) -> None:
    """The router is killed and restarted mid-run (a partition: the clock pauses), then the coordinator is
    SIGKILLed and resumed from its checkpoint: the decisions are those of the in-process run."""
    from coordinator.fleet import in_process, resumed_config

    run, run_dir, minutes = "faults", tmp_path / "run", 14
    coord = coordinator(bus, run, "--run-dir", str(run_dir), minutes=minutes, deadline=60, minute_s=0.4)
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
        kill_all(coord, resumed, *agents)
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


def test_a_killed_agent_rejoins_and_a_hung_agent_costs_one_deadline(bus: Bus, tmp_path: Path) -> None:
    """Agent 1 is SIGKILLed mid-turn and restarted; then agent 2 is SIGSTOPped mid-turn and SIGCONTed."""
    run, minutes, deadline, out = "agents", 40, 1.5, tmp_path / "result.json"
    coord = coordinator(bus, run, "--json", str(out), minutes=minutes, deadline=deadline, minute_s=0.4)
    agents = {i: bus.agent(i, run, grace=60) for i in range(3)}
    watch = {i: bus.watch(i, run) for i in (1, 2)}
    try:
        coord.wait_for("all 3 agents joined")
        t_kill = next_turn(watch[1].turns, watch[1].stop_after_an_answer(agents[1], 2) + 1)
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
        kill_all(coord, *agents.values())
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
    coord = coordinator(bus, run, minutes=60, deadline=60, minute_s=0.4)
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
        kill_all(coord, *agents)
    lines = coord.lines
    assert lines.index(coord.wait_for("agent 1 left")) < lines.index(coord.wait_for("agent 1 is back")) < lines.index(gone)
    assert "silent for" not in coord.text


def test_a_stopped_coordinator_stops_its_agents_within_the_grace_period(bus: Bus) -> None:
    """SIGTERM: the coordinator publishes stop and every agent leaves at once; SIGKILL: they leave after the grace period."""
    grace = 4.0
    for sig, run in ((signal.SIGTERM, "term"), (signal.SIGKILL, "kill")):
        coord = coordinator(bus, run, minutes=60, deadline=30, minute_s=0.5)
        agents = [bus.agent(i, run, grace=grace) for i in range(3)]
        try:
            coord.wait_for("minute 2/60")
            coord.proc.send_signal(sig)
            t0 = time.monotonic()
            codes = [a.finish(grace + 20) for a in agents]
            took = time.monotonic() - t0
            rc = coord.finish(30)
        finally:
            kill_all(coord, *agents)
        if sig == signal.SIGTERM:
            assert rc == 143 and "published stop at minute" in coord.text
            assert codes == [0, 0, 0] and took < grace
            assert all("the coordinator ended the run at minute" in a.text for a in agents)
            assert not any("the coordinator's token is gone" in a.text for a in agents)
        else:
            assert codes == [2, 2, 2] and grace < took < grace + 15
            assert all(f"has been gone for more than {grace:g} s (the grace period); leaving" in a.text for a in agents)
