"""The written protocol: forecasts per sector, the city's content hash, and an outside client that follows a run.

The outside client (``tests/bus/outside_client.py``) is written from
``docs/PROTOCOL.md`` alone: it imports zenoh and msgpack and nothing of this
project.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from agents.demand_tables import DemandTables
from agents.rollout import RolloutConfig, agent_costs, prepare_step
from agents.sector_forecasts import AgentForecasts, needed_sectors
from bus.checks import Bounds, Rejections
from bus.forecast_messages import sector_message
from bus.keys import Keys
from bus.wire import Dropoffs, WireError
from city.fingerprint import city_sha256
from city.scenario import load_city
from tests.agents.test_planning_speed import forecast, seeded_state


@contextlib.contextmanager
def _answering(session, key: str, answer: Callable[[str], bytes], asked: list[str] | None = None) -> Iterator[None]:
    """A stand-in coordinator: a queryable on ``key`` that answers each query with ``answer(its key)``, from a thread."""
    import zenoh

    answers = session.declare_queryable(key, zenoh.handlers.FifoChannel(64))
    done = threading.Event()

    def serve() -> None:
        while not done.is_set():
            if (query := answers.try_recv()) is None:
                time.sleep(0.01)
                continue
            if asked is not None:
                asked.append(str(query.key_expr))
            query.reply(query.key_expr, answer(str(query.key_expr)))
            query.drop()

    thread = threading.Thread(target=serve)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join(5)
        answers.undeclare()


def _pieces(city, fc, config: RolloutConfig, sectors) -> AgentForecasts:
    """A taxi's store fed the given sectors of ``fc`` and the drop-offs, as the bus would hand them in."""
    keys = Keys("p")
    got = AgentForecasts(city, config, Bounds(taxis=1, nodes=city.n_nodes, sectors=city.n_sectors, minutes=60), Rejections(print))
    for s in sectors:
        got.on_sector(sector_message(fc, city, 0, int(s)).encode(), keys.forecast(int(s)))
    got.on_dropoffs(Dropoffs(hour=0, delta=fc.delta).encode(), keys.dropoffs)
    return got


@pytest.mark.usefixtures("compiled_kernels")
def test_a_taxi_plans_on_its_local_sectors_exactly_as_on_the_whole_forecast() -> None:
    city = load_city("synthetic")
    fc = forecast(city, np.random.default_rng(4))
    obs = seeded_state(city, 2, taxis=30, requests=40)
    surge = RolloutConfig(horizon=5, samples=24)
    free = np.flatnonzero(obs.tau == 0)[:6]
    for cfg in (surge, dataclasses.replace(surge, ce="counts")):  # standard's counts draw sector by sector too
        whole = prepare_step(city, cfg, obs, DemandTables.build(city, fc, cfg.ce, cfg.seed), 7)
        for agent in free.tolist():
            sectors = needed_sectors(city, cfg, int(obs.pos[agent]))
            assert 0 < sectors.size < city.n_sectors  # local sectors only
            store = _pieces(city, fc, cfg, sectors)
            assert store.missing(0, sectors) == [] and store.tables(0, np.arange(city.n_sectors)) is None
            local = prepare_step(city, cfg, obs, store.tables(0, sectors), 7)
            committed = whole.base_controls[:agent]
            np.testing.assert_array_equal(agent_costs(local, committed, agent)[1], agent_costs(whole, committed, agent)[1])
    # a planner with standard certainty equivalence or map scope follows every sector
    for cfg in (RolloutConfig(ce="standard", base="ia", scope="map"), dataclasses.replace(surge, ce="standard")):
        assert needed_sectors(city, cfg, int(obs.pos[0])).tolist() == list(range(city.n_sectors))
    store = _pieces(city, fc, surge, needed_sectors(city, surge, int(obs.pos[free[0]]))[:-1])
    assert store.tables(0, needed_sectors(city, surge, int(obs.pos[free[0]]))) is None  # a piece missing: no tables yet


def test_sector_pieces_are_checked_against_the_city() -> None:
    city = load_city("synthetic")
    fc = forecast(city, np.random.default_rng(1))
    store = _pieces(city, fc, RolloutConfig(), [])
    keys = Keys("p")
    good = sector_message(fc, city, 0, 1)
    for msg, where, reason in [
        (good, keys.forecast(2), "field 'sector' is 1, on the key of sector 2"),
        (dataclasses.replace(good, nodes=good.nodes[::-1].copy()), keys.forecast(1), "not sector 1's"),
        (dataclasses.replace(good, rho=good.rho[:-1]), keys.forecast(1), "field 'rho' has shape"),
        (dataclasses.replace(good, beta=-good.beta), keys.forecast(1), "field 'beta' holds a negative"),
        (dataclasses.replace(good, hour=1), keys.forecast(1), "field 'hour' is 1, the episode has hours 0..0"),
    ]:
        with pytest.raises(WireError, match=reason):
            store.on_sector(msg.encode(), where)
    with pytest.raises(WireError, match=f"field 'delta' has shape \\[3\\], this city needs \\[{city.n_nodes}\\]"):
        store.on_dropoffs(Dropoffs(hour=0, delta=np.ones(3)).encode(), keys.dropoffs)
    assert store.slices == {}


def test_the_city_hash_tells_cities_of_the_same_size_apart(capsys: pytest.CaptureFixture) -> None:
    from agents.taxi import AgentConfig, TaxiAgent
    from agents.taxi_join import OtherCity
    from bus.session import SessionArgs
    from bus.wire import RunSpec
    from city.fingerprint import code_version

    city = load_city("synthetic")
    assert city_sha256(city) == city_sha256(load_city("synthetic"))
    pickup = city.pickup.copy()
    pickup[np.flatnonzero(pickup)[0]] = False
    other = dataclasses.replace(city, pickup=pickup)
    assert other.summary() == city.summary() and city_sha256(other) != city_sha256(city)
    agent = TaxiAgent(AgentConfig(index=0, run="h", bus=SessionArgs(mode="client", connect=["tcp/127.0.0.1:1"])))
    spec = RunSpec(run="h", scenario="synthetic", data_dir=None, city=city.summary(), taxis=2, minutes=3, policy="surge",
                   rollout={"samples": 4}, deadline_s=5.0, city_sha256=city_sha256(other), code="surge 0.0.0+000000000000")
    with pytest.raises(OtherCity, match=r"agent 0 does not join run 'h': this host's synthetic city has content hash [0-9a-f]{16}…, "
                                        r"the coordinator's [0-9a-f]{16}…"):
        agent._accept_spec(spec.encode())
    agent._accept_spec(dataclasses.replace(spec, city_sha256=city_sha256(city)).encode())
    err = capsys.readouterr().err
    assert f"warning: this host runs {code_version()}, the coordinator surge 0.0.0+000000000000" in err


CLI = [sys.executable, "-m", "coordinator.cli"]
OUTSIDE = [sys.executable, str(Path(__file__).with_name("outside_client.py"))]


@pytest.mark.usefixtures("compiled_kernels")
def test_an_outside_client_follows_a_run_and_rebuilds_every_taxis_position(tmp_path: Path) -> None:
    """A secured run of 2 taxis; the outside client holds the read-only observer certificate, and subscribes key by key."""
    from bus.certs import make_certs
    from bus.router import free_tcp_port, wait_for_tcp
    from city.sim import FleetSim
    from coordinator.run_config import FleetConfig

    certs = tmp_path / "certs"
    make_certs(certs, 2)
    port = free_tcp_port()
    endpoint = f"tls/127.0.0.1:{port}"
    bus = ["--connect", endpoint, "--certs", str(certs)]
    run, minutes, result_path, seen_path = "outside", 6, tmp_path / "result.json", tmp_path / "seen.json"
    procs = [subprocess.Popen([*CLI, "router", "--certs", str(certs), "--listen", endpoint], stderr=subprocess.DEVNULL)]
    try:
        wait_for_tcp("127.0.0.1", port, 30)
        procs.append(subprocess.Popen([*CLI, "coordinator", *bus, "--run", run, "--taxis", "2", "--minutes", str(minutes),
                                       "--forecast", "true-rate", "--samples", "30", "--deadline", "120", "--join-timeout", "300",
                                       "--json", str(result_path)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True))
        client = subprocess.Popen([*OUTSIDE, endpoint, run, str(seen_path), str(certs), "observer"], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True)
        procs.append(client)
        assert client.stdout.readline().strip() == "ready", client.stderr.read()
        procs.append(subprocess.Popen([*CLI, "agents", *bus, "--run", run, "--ids", "0-1"], stderr=subprocess.DEVNULL))
        _, err = procs[1].communicate(timeout=240)
        assert procs[1].returncode == 0, err
        assert client.wait(60) == 0, client.stderr.read()
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
            p.wait(10)
    seen, result = json.loads(seen_path.read_text()), json.loads(result_path.read_text())
    assert seen["taxis"] == 2 and seen["minutes"] == minutes and result["fallbacks"] == 0
    assert sorted(map(int, seen["positions"])) == list(range(minutes))
    # the world replayed with the coordinator's controls puts every taxi where the client saw it, every minute
    scen, requests, start, _ = FleetConfig(taxis=2, minutes=minutes).instance()
    assert seen["city_sha256"] == city_sha256(scen.city)
    sim = FleetSim(scen.city, requests, start)
    for t, controls in enumerate(result["controls"]):
        obs = sim.observe()
        assert seen["positions"][str(t)] == obs.pos.tolist() and seen["outstanding"][str(t)] == obs.req_index.size
        free = np.flatnonzero(obs.tau == 0).tolist()
        assert {int(a): c for a, c in seen["committed"].get(str(t), {}).items()} == {a: controls[a] for a in free}
        sim.step(np.asarray(controls, dtype=np.int32))
    assert seen["moves_checked"] > 0


def test_a_taxi_follows_its_sectors_and_fetches_what_it_missed_when_it_moves() -> None:
    """A real zenoh session: the taxi's subscriptions follow its sectors; a stand-in coordinator answers the sector queries."""
    from bus.session import Inbox, SessionArgs, open_session

    city = load_city("synthetic")
    fc = forecast(city, np.random.default_rng(3))
    keys = Keys("follow")
    asked: list[str] = []
    with (open_session(SessionArgs(mode="peer")) as session,
          _answering(session, keys.all_forecasts, lambda k: sector_message(fc, city, 0, Keys.agent_of(k)).encode(), asked)):
        inbox = Inbox()
        store = _pieces(city, fc, RolloutConfig(), [])
        store.attach(session, inbox, keys)
        store.follow(np.array([1, 2]), hour=0)
        assert sorted(store.slices[0]) == [1, 2] and store.fetched == 2
        store.follow(np.array([2, 3]), hour=0)  # moved: 1 is dropped, 3 fetched, 2 kept
        assert sorted(store.slices[0]) == [1, 2, 3] and store.fetched == 3 and asked == [keys.forecast(s) for s in (1, 2, 3)]
        for s in range(5):  # the next hour's publication reaches only the followed sectors
            session.put(keys.forecast(s), sector_message(fc, city, 1, s).encode())
        got = sorted(Keys.agent_of(item[1]) for item in iter(lambda: inbox.get(timeout=1.0), None))
        assert got == [2, 3]
        store.close()


def test_an_agent_on_another_city_refuses_to_join_at_once(capsys: pytest.CaptureFixture) -> None:
    """A real session answers ``spec`` with another city's hash: the agent exits with one line, not after its join timeout."""
    from agents.taxi import AgentConfig, agent_main
    from bus.router import free_tcp_port
    from bus.session import SessionArgs, open_session
    from bus.wire import RunSpec

    city = load_city("synthetic")
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    keys = Keys("refuse")
    spec = RunSpec(run="refuse", scenario="synthetic", data_dir=None, city=city.summary(), taxis=1, minutes=2, policy="surge",
                   rollout={"samples": 4}, deadline_s=5.0, city_sha256="f" * 64, code="surge 0.0.0+000000000000")
    with open_session(SessionArgs(mode="peer", listen=[endpoint])) as session, _answering(session, keys.spec, lambda _: spec.encode()):
        t0 = time.monotonic()
        code = agent_main(AgentConfig(index=0, run="refuse", bus=SessionArgs(mode="peer", connect=[endpoint]), join_timeout_s=120))
    assert code == 2 and time.monotonic() - t0 < 60
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"surge agent 0: error: agent 0 does not join run 'refuse': this host's synthetic city has content hash "
                              f"{city_sha256(city)[:16]}…, the coordinator's ffffffffffffffff…")


@pytest.mark.usefixtures("compiled_kernels")
def test_across_an_hour_the_per_sector_forecasts_give_the_in_process_decisions() -> None:
    """62 minutes: the predictor service publishes hour 1's sectors mid-run, and taxis that moved meanwhile follow theirs."""
    from coordinator.fleet import in_process, run_local_fleet
    from coordinator.run_config import FleetConfig

    cfg = FleetConfig(run="hours", taxis=2, minutes=62, options={"forecast": "true-rate", "samples": 20, "horizon": 3},
                      deadline_s=120, join_timeout_s=300, predictor=True)
    dist = run_local_fleet(cfg, secure=False)
    assert dist["fallbacks"] == 0 and dist["agents_exit_codes"] == [0, 0]
    assert dist["decisions_sha256"] == in_process(cfg)["decisions_sha256"]
