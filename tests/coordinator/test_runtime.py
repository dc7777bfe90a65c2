"""The distributed runtime over a real zenoh router on loopback, with one process per taxi.

Small fleets and few samples keep these fast; the processes, sessions,
router and msgpack messages are the real ones.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Iterator

import pytest

from bus.certs import make_certs
from bus.router import free_tcp_port, wait_for_tcp
from coordinator.fleet import in_process, run_local_fleet
from coordinator.run_config import FleetConfig

CLI = [sys.executable, "-m", "coordinator.cli"]
pytestmark = pytest.mark.usefixtures("compiled_kernels")


@pytest.mark.parametrize(
    ("policy", "options", "predictor", "secure", "threads"),
    [("surge", {"forecast": "true-rate", "samples": 100}, True, True, "share"), ("garces2023", {"samples": 50, "horizon": 5}, False, False, 1)],
)
def test_distributed_run_makes_the_in_process_decisions(policy: str, options: dict, predictor: bool, secure: bool,
                                                        threads: int | str) -> None:
    """surge takes its forecasts from a predictor service process over mutual TLS and access control;
    its agents share the host's cores among those planning at the time (the default); garces2023 takes
    its forecasts from the coordinator, on an insecure bus, its agents planning on one kernel thread each.
    Turns go out as their dependencies commit, and the in-process reference plans strictly one agent
    after another with every core."""
    cfg = FleetConfig(run=f"same-{policy}", taxis=3, minutes=8, policy=policy, options=options, deadline_s=120,
                      join_timeout_s=300, predictor=predictor)
    dist = run_local_fleet(cfg, secure=secure, agent_threads=threads)
    ref = in_process(cfg)
    assert dist["secured"] is secure
    assert dist["fallbacks"] == 0 and dist["agents_exit_codes"] == [0, 0, 0]
    assert sum(dist["planned_per_agent"]) > 0
    assert any(c < f for c, f in zip(dist["critical_path"], dist["free_per_minute"]))  # some agents took turns side by side
    assert dist["decisions_sha256"] == ref["decisions_sha256"]
    assert dist["total_cost"] == ref["total_cost"] and dist["served"] == ref["served"]


@pytest.fixture(scope="module")
def router(tmp_path_factory: pytest.TempPathFactory) -> Iterator[list[str]]:
    """A secured router; the flags that reach it."""
    certs = tmp_path_factory.mktemp("runtime") / "certs"
    make_certs(certs, 3)
    port = free_tcp_port()
    endpoint = f"tls/127.0.0.1:{port}"
    proc = subprocess.Popen([*CLI, "router", "--certs", str(certs), "--listen", endpoint], stderr=subprocess.PIPE, text=True)
    try:
        wait_for_tcp("127.0.0.1", port, 30)
        yield ["--connect", endpoint, "--certs", str(certs)]
    finally:
        proc.terminate()
        proc.wait(10)


IMPOSTOR = """
import sys, time, zenoh
from bus.keys import Keys
from bus.session import SessionArgs, open_session
from bus.wire import Control
keys, deadline = Keys(sys.argv[1]), float(sys.argv[4])
with open_session(SessionArgs(mode="client", connect=[sys.argv[2]], certs=sys.argv[3], identity="taxi-1")) as s:
    turns = s.declare_subscriber(keys.turn(1), zenoh.handlers.FifoChannel(16))
    token = s.liveliness().declare_token(keys.alive(1))
    turns.recv()
    s.put(keys.control(1), b"not msgpack at all")
    s.put(keys.control(1), Control(t=0, agent=0, control=0, epoch=0).encode())
    time.sleep(deadline + 0.5)
    token.undeclare()
"""


def test_silent_agent_gets_base_controls_bad_messages_are_ignored_and_a_restarted_agent_rejoins(router: list[str], tmp_path: Path) -> None:
    run, out, deadline = "rejoin", tmp_path / "result.json", 2.0
    coord = subprocess.Popen(
        [*CLI, "coordinator", *router, "--run", run, "--taxis", "3", "--minutes", "30", "--forecast", "true-rate",
         "--samples", "50", "--deadline", str(deadline), "--minute-seconds", "0.5", "--join-timeout", "300", "--json", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    others = subprocess.Popen([*CLI, "agents", *router, "--run", run, "--ids", "0,2"], stderr=subprocess.PIPE, text=True)
    impostor = subprocess.run([sys.executable, "-c", IMPOSTOR, run, router[1], router[3], str(deadline)], capture_output=True,
                              text=True, timeout=120)
    assert impostor.returncode == 0, impostor.stderr
    restarted = subprocess.Popen([*CLI, "agents", *router, "--run", run, "--ids", "1"], stderr=subprocess.PIPE, text=True)
    try:
        _, err = coord.communicate(timeout=180)
        assert coord.returncode == 0, err
        assert others.wait(60) == 0 and restarted.wait(60) == 0
    finally:
        for p in (coord, others, restarted):
            p.kill()
    result = json.loads(out.read_text())
    assert "ignored: surge/rejoin/control/1: not msgpack" in err
    assert "ignored: surge/rejoin/control/1: control of agent 0 on another agent's key" in err
    assert f"agent 1 silent for {deadline:g} s; base control used" in err and "agent 1 left" in err
    assert result["fallbacks_per_agent"][0] == 0 and result["fallbacks_per_agent"][2] == 0
    assert result["fallbacks_per_agent"][1] >= 1
    assert result["planned_per_agent"][1] >= 1, "the restarted agent never took a turn"
    assert len(result["controls"]) == 30


def test_coordinator_without_agents_fails_in_one_line(router: list[str]) -> None:
    proc = subprocess.run([*CLI, "coordinator", *router, "--run", "lonely", "--taxis", "2", "--forecast", "true-rate",
                           "--join-timeout", "1"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines()[-1] == "surge: error: run 'lonely': 0 of 2 agents joined within 1 s; missing 0, 1"


def test_fleet_command_checks_against_in_process(tmp_path: Path) -> None:
    out = tmp_path / "fleet.json"
    t0 = time.monotonic()
    proc = subprocess.run([*CLI, "fleet", "--taxis", "2", "--minutes", "5", "--forecast", "true-rate", "--samples", "50", "--check",
                           "--json", str(out)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "decisions identical" in proc.stdout and "minute 5/5" in proc.stderr
    assert "secured: mutual TLS and access control" in proc.stderr and "bus: mutual TLS, access control" in proc.stdout
    doc = json.loads(out.read_text())
    assert doc["same_decisions"] and doc["wall_seconds"] < time.monotonic() - t0


def test_demo_runs_the_fleet_and_ends_with_its_table_and_pictures(tmp_path: Path) -> None:
    """`make demo`'s command, small: the README's main job must run end to end, quietly on a healthy bus."""
    proc = subprocess.run([*CLI, "demo", "--taxis", "2", "--minutes", "3", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "decisions identical" in proc.stdout and "minute 3/3" in proc.stderr
    assert "ignored:" not in proc.stderr, "a healthy demo's own messages were refused"
    rows = [line.split()[0:2] for line in proc.stdout.splitlines() if line.startswith(("surge (", "greedy ("))]
    assert rows == [["surge", "(distributed)"], ["surge", "(in-process)"], ["greedy", "(in-process)"]]
    for name in ("demo.json", "demo-surge-map.png", "demo-surge-vs-greedy.gif"):
        assert (tmp_path / name).stat().st_size > 0, name


ASK = """
import sys
from bus.session import SessionArgs, open_session
from bus.wire import ForecastMsg, ForecastRequest, decode
with open_session(SessionArgs(mode="client", connect=[sys.argv[1]], certs=sys.argv[2], identity="coordinator")) as s:
    for req in (b"junk", ForecastRequest(hour=0, when="2022-11-17T19:00:00").encode(),
                ForecastRequest(hour=1, when="2022-11-17T20:00:00").encode()):
        for rep in s.get("surge/ask/predictor", payload=req, timeout=20.0):
            if rep.ok is not None:
                msg = decode(rep.ok.payload.to_bytes(), ForecastMsg)
                print("ok", msg.hour, msg.eta.shape[0], round(float(msg.eta.sum()), 6))
            else:
                print("err", rep.err.payload.to_bytes().decode())
"""


def test_predictor_service_refuses_bad_requests_and_keeps_serving(router: list[str], synthetic_scenario) -> None:
    import datetime as dt

    serve = subprocess.Popen([*CLI, "predictor", "serve", *router, "--run", "ask", "--forecast", "true-rate"],
                             stderr=subprocess.PIPE, text=True)
    try:
        assert "serving true-rate forecasts" in serve.stderr.readline()
        out = subprocess.run([sys.executable, "-c", ASK, router[1], router[3]], capture_output=True, text=True, timeout=120)
    finally:
        serve.terminate()
        serve.wait(10)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].startswith("err surge/ask/predictor: not msgpack")
    from agents.forecast_providers import make_provider

    eta = make_provider("true-rate").forecast(synthetic_scenario.world, dt.datetime(2022, 11, 17, 19)).eta
    assert lines[1] == f"ok 0 {synthetic_scenario.city.n_sectors} {round(float(eta.sum()), 6)}"
    assert lines[2].startswith("ok 1 ") and len(lines) == 3
