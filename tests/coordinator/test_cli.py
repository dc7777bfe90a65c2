"""The command line: clear one-line errors with exit code 2, and real runs."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from coordinator.cli import main


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "coordinator.cli", *args], capture_output=True, text=True, timeout=600)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["evaluate", "--policies", "greedy", "teleport"], "unknown policy 'teleport'"),
        (["evaluate", "--scenario", "atlantis"], "unknown scenario 'atlantis'"),
        (["evaluate", "--scenario", "nyc"], "needs --data DIR"),
        (["evaluate", "--scenario", "nyc", "--data", "/nonexistent/dir"], "data directory /nonexistent/dir does not exist"),
        (["evaluate", "--data", "/nonexistent/dir"], "data directory /nonexistent/dir does not exist"),
        (["predictor", "train", "--out", "unused", "--data", "/nonexistent/dir"], "data directory /nonexistent/dir does not exist"),
        (["evaluate", "--policies", "surge:adaptive=0"], "option adaptive='0' is not accepted; adaptive takes a number above 0 or none"),
        (["evaluate", "--policies", "surge:samples"], "option 'samples' is not key=value"),
        (["evaluate", "--policies", "greedy:speed=2"], "policy 'greedy': unknown option 'speed'; it takes no options"),
        (["evaluate", "--policies", "surge:nonsense=3"], "policy 'surge': unknown option 'nonsense'; its options are forecast, model, horizon"),
        (["evaluate", "--policies", "surge:horizon=abc"], "policy 'surge': option horizon='abc' is not accepted; horizon takes an integer from 1 to 240"),
        (["evaluate", "--policies", "surge:samples=0"], "option samples='0' is not accepted; samples takes an integer from 1 to 1,000,000"),
        (["evaluate", "--policies", "surge:prune=-1"], "prune takes an integer of at least 0 or auto or none"),
        (["evaluate", "--policies", "surge:forecast=crystal-ball"], "forecast takes one of model, previous-hour, true-rate"),
        (["evaluate", "--policies", "oracle-auction:window=1.5"], "policy 'oracle-auction': option window='1.5' is not accepted"),
        (["fleet", "--policy", "garces2023:ce=fuzzy"], "policy 'garces2023': option ce='fuzzy' is not accepted; ce takes one of limited, standard, counts"),
        (["evaluate", "--resume"], "--resume needs --json"),
        (["fleet", "--policy", "greedy"], "the distributed runtime runs rollout policies"),
        (["fleet", "--deadline", "0"], "--deadline and --join-timeout must be positive"),
        (["fleet", "--grace", "0"], "--partition-timeout and --grace must be positive"),
        (["coordinator", "--resume", "/nonexistent"], "/nonexistent/checkpoint.json: no such file: nothing to resume"),
        (["coordinator", "--connect", "7447"], "zenoh endpoint '7447': expected PROTOCOL/ADDRESS"),
        (["coordinator", "--run", "a/b"], "run name 'a/b'"),
        (["agents", "--ids", "0-x"], "--ids '0-x': '0-x' is not N or N-M"),
        (["router", "--config", "/nonexistent.json5"], "zenoh config /nonexistent.json5: no such file"),
        (["report", "/nonexistent.json"], "/nonexistent.json: no such file"),
        (["predictor", "serve", "--forecast", "bogus"], "unknown forecast 'bogus'"),
        (["predictor", "serve"], "forecast 'model' needs a trained predictor"),
        (["predictor", "train", "--out", "unused", "--max-reviews", "0"], "--max-reviews must be at least 1, got 0"),
    ],
)
def test_bad_options_give_one_line_and_exit_2(args: list[str], message: str, capsys: pytest.CaptureFixture) -> None:
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("args", [["evaluate", "--hours", "25"], ["evaluate", "--seeds", "0"], ["evaluate", "--date", "2022-13-01"],
                                  ["predictor", "train", "--out", "unused", "--window", "2"], ["fleet", "--agent-threads", "0"],
                                  ["agents", "--ids", "0", "--agent-threads", "two"]])
def test_bad_flag_values_are_rejected_by_argparse(args: list[str]) -> None:
    proc = run_cli(*args)
    assert proc.returncode == 2
    assert "error:" in proc.stderr.splitlines()[-1]


def test_every_subcommand_has_help() -> None:
    for sub in (["evaluate"], ["city"], ["demand"], ["demo"], ["report"], ["fleet"], ["router"], ["coordinator"], ["agents"], ["predictor", "serve"], ["bench", "city"], ["bench", "sim"]):
        proc = run_cli(*sub, "--help")
        assert proc.returncode == 0, proc.stderr
        assert "usage: surge" in proc.stdout


def test_evaluate_small_run_writes_results_json(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    proc = run_cli("evaluate", "--hours", "19", "--seeds", "2", "--taxis", "20", "--minutes", "15",
                   "--policies", "greedy", "ia", "oracle", "--json", str(out), "--plot", str(tmp_path / "r.png"))
    assert proc.returncode == 0, proc.stderr
    assert "[6/6]" not in proc.stderr and "[2/2]" in proc.stderr  # progress per instance
    doc = json.loads(out.read_text())
    assert doc["schema"] == "surge.results/1" and doc["scenario"] == "synthetic"
    assert set(doc["city"]) == {"intersections", "streets", "sectors"}
    assert len(doc["episodes"]) == 6
    ep = doc["episodes"][0]
    assert set(ep) >= {"hour", "seed", "policy", "total_cost", "outstanding_end", "served",
                       "wait_overhead_per_served", "plan_seconds_per_step", "plan_cpu_seconds_per_step", "decisions_sha256"}
    assert "oracle" in proc.stdout and "total cost" in proc.stdout
    assert (tmp_path / "r.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_report_reads_a_results_file(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    assert run_cli("evaluate", "--hours", "19", "--seeds", "2", "--taxis", "20", "--minutes", "10",
                   "--policies", "greedy", "ia", "--json", str(out)).returncode == 0
    proc = run_cli("report", str(out), "--policy", "ia", "--json", str(tmp_path / "rep.json"), "--plot", str(tmp_path / "rep.png"))
    assert proc.returncode == 0, proc.stderr
    assert "total cost" in proc.stdout and "ia paired with each policy" in proc.stdout
    rep = json.loads((tmp_path / "rep.json").read_text())
    assert rep["schema"] == "surge.report/1" and rep["seeds"] == [0, 1]
    assert [r["against"] for r in rep["comparison"]] == ["greedy"]
    assert (tmp_path / "rep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    doc = json.loads(out.read_text())
    doc["episodes"][2].pop("total_cost")
    out.write_text(json.dumps(doc))
    proc = run_cli("report", str(out))
    assert proc.returncode == 2 and proc.stderr.strip() == f"surge: error: {out}: episode 2 has no 'total_cost' field"


def _children(pid: int) -> set[int]:
    kids = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rpartition(")")[2].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            kids.add(int(stat.parent.name))
    return kids


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table from /proc")
def test_sigterm_stops_the_worker_pool_and_keeps_finished_instances(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    proc = subprocess.Popen(
        [sys.executable, "-m", "coordinator.cli", "evaluate", "--hours", "19", "--seeds", "20", "--taxis", "40",
         "--minutes", "60", "--policies", "greedy", "ia", "--jobs", "2", "--json", str(out)],
        stderr=subprocess.PIPE, text=True,
    )
    try:
        line = proc.stderr.readline()
        while line and not line.startswith("[1/20]"):
            line = proc.stderr.readline()
        assert line.startswith("[1/20]"), "the run ended before its first instance"
        workers = _children(proc.pid)
        assert workers
        proc.send_signal(signal.SIGTERM)
        rest = proc.stderr.read()
        assert proc.wait(timeout=60) == 128 + signal.SIGTERM
    finally:
        proc.kill()
    assert "surge: terminated" in rest and "Traceback" not in rest
    deadline = time.monotonic() + 30
    while any(Path(f"/proc/{w}").exists() for w in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [w for w in workers if Path(f"/proc/{w}").exists()], "worker processes outlived the run"
    done = json.loads(out.read_text())["episodes"]
    assert 2 <= len(done) < 40 and len(done) % 2 == 0  # whole instances, and not the full run
