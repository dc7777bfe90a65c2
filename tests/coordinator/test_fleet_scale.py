"""Lean agents: forked from a preloaded parent with no zenoh session, they open their own; the city is mapped, not read; the bench reports.

The fork server of :func:`coordinator.fleet.agent_context` imports
:mod:`agents.preload` and then forks every agent; zenoh must work in the
children, each with its own session opened after the fork.
"""

from __future__ import annotations

import json
import os
import queue
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bus.router import free_tcp_port, router_main, wait_for_tcp
from bus.session import SessionArgs, open_session
from city.scenario import load_city
from coordinator.fleet import agent_context
from tests.conftest import SHARED_DATA

pytestmark = pytest.mark.usefixtures("compiled_kernels")


def _forked_agent(endpoint: str, key: str, ready: str) -> None:
    """In a forked child: a session of its own, waiting for the test to listen, then one message about itself."""
    from agents.rollout import warm_up

    warm_up()  # the parallel kernel, loaded after the fork
    with open_session(SessionArgs(mode="client", connect=[endpoint])) as s:
        while not list(s.get(ready, timeout=2.0)):
            pass
        s.put(key, json.dumps({"pid": os.getpid(), "parent": os.getppid(), "preloaded": "agents.preload" in sys.modules,
                               "torch": "torch" in sys.modules, "scipy.sparse": "scipy.sparse.csgraph" in sys.modules}))


def test_agents_forked_from_the_preloaded_server_use_zenoh() -> None:
    import multiprocess as mp

    port = free_tcp_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = mp.get_context("spawn").Process(target=router_main, args=(SessionArgs(mode="router", listen=[endpoint]),))
    router.start()
    ctx = agent_context()
    agents = [ctx.Process(target=_forked_agent, args=(endpoint, f"fork-test/said/{i}", "fork-test/ready")) for i in range(2)]
    try:
        wait_for_tcp("127.0.0.1", port, 30)
        got: queue.SimpleQueue = queue.SimpleQueue()
        with open_session(SessionArgs(mode="client", connect=[endpoint])) as s:
            sub = s.declare_subscriber("fork-test/said/*", lambda x: got.put(json.loads(x.payload.to_bytes())))
            ready = s.declare_queryable("fork-test/ready", lambda q: (q.reply(q.key_expr, b"yes"), q.drop()))
            for p in agents:
                p.start()
            said = [got.get(timeout=120) for _ in agents]
            sub.undeclare()
            ready.undeclare()
        for p in agents:
            p.join(30)
    finally:
        for p in [*agents, router]:
            if p.is_alive():
                p.terminate()
            p.join(10)
    assert [p.exitcode for p in agents] == [0, 0]
    assert {m["pid"] for m in said} == {p.pid for p in agents}
    assert all(m["parent"] != os.getpid() for m in said) and len({m["parent"] for m in said}) == 1  # forked by the one server
    assert all(m["preloaded"] and not m["torch"] and not m["scipy.sparse"] for m in said)


def test_a_mapped_city_is_the_read_one() -> None:
    read, mapped = load_city("synthetic"), load_city("synthetic", mmap=True)
    for name in ("xy", "indptr", "indices", "node_sector", "sector_adj", "dist", "next_hop", "dist_m"):
        a, b = getattr(read, name), getattr(mapped, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
        assert isinstance(b.base, np.memmap) and b.flags.writeable, name  # pages of the file, typed as numba expects
    assert np.array_equal(mapped.dist_t, read.dist.T) and mapped.dist_t.flags.c_contiguous


@pytest.mark.parametrize("policy", ["surge", "garces2023"])
def test_bench_fleet_on_the_real_map_prints_and_writes_every_figure(policy: str, tmp_path: Path) -> None:
    """The distributed run on the real map, turns in waves, against sequential turns in-process."""
    data = Path(os.environ.get("SURGE_TEST_DATA", SHARED_DATA))
    if not data.is_dir():
        pytest.skip("../shared/data not available")
    out = tmp_path / "fleet.json"
    run = subprocess.run([sys.executable, "-m", "coordinator.cli", "bench", "fleet", "--scenario", "nyc", "--data", str(data),
                          "--taxis", "6", "--minutes", "3", "--policy", policy, "--forecast", "true-rate", "--samples", "20",
                          "--horizon", "4", "--insecure", "--hosts", "2", "--json", str(out)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    rep = json.loads(out.read_text())
    assert rep["same_decisions"] and rep["fallbacks"] == 0
    assert any(c < f for c, f in zip(rep["critical_path"], rep["free_per_minute"]))  # some turns went out side by side
    assert rep["memory"]["agents_measured"] == 6 and rep["memory"]["agents_pss_mb"] > 0
    assert rep["ready_seconds"] > 0 and rep["traffic"]["messages_per_minute"] > 0
    assert len(rep["critical_path"]) == 3 and set(rep["projected_minute_seconds_median"]) == {"2", "one per agent"}
    assert rep["config"]["agent_threads"] == "share"  # the default: the host's cores split among the agents planning
    assert rep["demand_source"].startswith("hourly-totals ")  # the real map at the real level of the hour, recorded
    for line in ("(share kernel threads each)", "decisions identical", "median minute: distributed", "agents' memory", "all agents ready",
                 "projected median minute"):
        assert line in run.stdout, line


def test_projection_splits_each_wave_over_the_hosts_and_keeps_its_slowest_agent() -> None:
    from coordinator.metrics import project_minutes

    waves = [[{"agents": [0, 1, 2, 3], "seconds": 2.0}, {"agents": [3], "seconds": 0.5}]]
    alone = {(0, 0): 0.3, (0, 1): 0.3, (0, 2): 0.3, (0, 3): 0.6}
    one, two, each = (project_minutes(waves, alone, [0.1], 4, h)[0] for h in (1, 2, None))
    assert one == pytest.approx(0.1 + 2.0 + 0.6)  # the measured waves; the lone agent's wave no faster than it alone
    assert two == pytest.approx(0.1 + 1.0 + 0.6)  # two agents of the first wave on each host
    assert each == pytest.approx(0.1 + 0.6 + 0.6)  # one agent a host: the slowest agent alone


def test_an_agent_maps_the_real_map_without_the_builders_imports() -> None:
    """What an agent imports to join a real-map run: no scipy graph code, no pyproj, no holidays, no torch."""
    data = Path(os.environ.get("SURGE_TEST_DATA", SHARED_DATA))
    if not data.is_dir():
        pytest.skip("../shared/data not available")
    load_city("nyc", data)  # the cache exists, as the command that starts a run makes sure
    code = ("import sys, agents.taxi; from city.scenario import load_city; c = load_city('nyc', sys.argv[1], mmap=True); "
            "print(c.n_nodes, sorted(m for m in ('scipy.sparse', 'pyproj', 'holidays', 'torch', 'shapely') if m in sys.modules))")
    run = subprocess.run([sys.executable, "-c", code, str(data)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split(" ", 1)[1].strip() == "[]"
