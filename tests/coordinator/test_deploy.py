"""A secured run across three network hosts: router and coordinator on one Linux network namespace, two groups of agents on two others.

Needs root (or CAP_NET_ADMIN) and iproute2; skipped where the namespaces
cannot be made.  ``deploy/netns.sh`` builds the three hosts, as a user would;
the run uses mutual TLS and access control with credentials made for the
router's address, as ``docs/runtime.md`` describes.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Iterator

import pytest

from bus.certs import make_certs
from coordinator.fleet import in_process
from coordinator.run_config import FleetConfig

ROOT = Path(__file__).resolve().parents[2]
NETNS = ROOT / "deploy" / "netns.sh"
pytestmark = pytest.mark.usefixtures("compiled_kernels")


@pytest.fixture(scope="module")
def hosts() -> Iterator[str]:
    if shutil.which("ip") is None or os.geteuid() != 0:
        pytest.skip("needs root and iproute2 for network namespaces")
    prefix = f"sg{os.getpid() % 100000}"
    up = subprocess.run(["bash", str(NETNS), "up", prefix, "3"], capture_output=True, text=True)
    if up.returncode != 0:
        subprocess.run(["bash", str(NETNS), "down", prefix, "3"], capture_output=True)
        pytest.skip(f"cannot make network namespaces here: {up.stderr.strip()[:200]}")
    try:
        yield prefix
    finally:
        subprocess.run(["bash", str(NETNS), "down", prefix, "3"], capture_output=True)


def on(host: str, *cmd: str) -> list[str]:
    return ["ip", "netns", "exec", host, sys.executable, "-m", "coordinator.cli", *cmd]


def test_agents_on_two_other_hosts_make_the_in_process_decisions(hosts: str, tmp_path: Path) -> None:
    h1, h2, h3, endpoint = f"{hosts}-h1", f"{hosts}-h2", f"{hosts}-h3", "tls/10.77.0.1:7447"
    out, certs = tmp_path / "result.json", tmp_path / "certs"
    make_certs(certs, 4, hosts=["10.77.0.1"])
    secured = ["--certs", str(certs)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    router = subprocess.Popen(on(h1, "router", *secured, "--listen", endpoint), stderr=subprocess.PIPE, text=True, env=env)
    procs = [router]
    try:
        wait = [sys.executable, "-c", "from bus.router import wait_for_tcp; wait_for_tcp('10.77.0.1', 7447, 30)"]
        for h in (h2, h3):
            subprocess.run(["ip", "netns", "exec", h, *wait], check=True, env=env, timeout=60)
        coord = subprocess.Popen(on(h1, "coordinator", *secured, "--connect", endpoint, "--run", "hosts", "--taxis", "4", "--minutes", "6",
                                    "--forecast", "true-rate", "--samples", "50", "--deadline", "120", "--join-timeout", "300", "--json", str(out)),
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        groups = [subprocess.Popen(on(h, "agents", *secured, "--connect", endpoint, "--run", "hosts", "--ids", ids),
                                   stderr=subprocess.PIPE, text=True, env=env) for h, ids in ((h2, "0-1"), (h3, "2-3"))]
        procs += [coord, *groups]
        _, err = coord.communicate(timeout=240)
        assert coord.returncode == 0, err
        assert [g.wait(60) for g in groups] == [0, 0]
    finally:
        for p in procs:
            p.terminate()
            p.wait(10)
    result = json.loads(out.read_text())
    ref = in_process(FleetConfig(taxis=4, minutes=6, options={"forecast": "true-rate", "samples": 50}))
    assert result["fallbacks"] == 0 and all(n > 0 for n in result["planned_per_agent"])  # every agent, on both hosts, planned
    assert result["decisions_sha256"] == ref["decisions_sha256"]
