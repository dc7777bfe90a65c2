"""The wire format, state deltas, key expressions and session settings (no bus needed)."""

from __future__ import annotations

import argparse
import subprocess
import sys

import msgpack
import numpy as np
import pytest

from agents.greedy import greedy_controls
from bus.delta import StateView, state_message
from bus.keys import Keys
from bus.session import (
    DEFAULT_ENDPOINT,
    DEFAULT_TLS_ENDPOINT,
    INSECURE_WARNING,
    SessionArgs,
)
from coordinator.cli.options import add_session_args, session_args
from bus.wire import (
    WIRE_VERSION,
    Ack,
    Control,
    Dropoffs,
    ForecastMsg,
    ForecastRequest,
    RunSpec,
    SectorForecast,
    Snapshot,
    State,
    Stop,
    Turn,
    WireError,
    decode,
)
from city.episode import episode_requests, initial_positions
from city.errors import ConfigError
from city.sim import FleetSim
from coordinator.cli.fleet import parse_ids


def test_every_message_round_trips_exactly() -> None:
    rng = np.random.default_rng(0)
    fc = ForecastMsg(hour=1, eta=rng.random(5), rho=rng.random(40), delta=rng.random(40), beta=rng.random((5, 5)))
    back = decode(fc.encode(), ForecastMsg)
    for name in ("eta", "rho", "delta", "beta"):
        assert np.array_equal(getattr(back, name), getattr(fc, name)) and getattr(back, name).dtype == np.float64
    assert back.beta.shape == (5, 5) and back.hour == 1
    spec = RunSpec(run="r", scenario="synthetic", data_dir=None, city={"intersections": 9}, taxis=3, minutes=5, policy="surge",
                   rollout={"horizon": 4, "samples": 10}, deadline_s=2.5, city_sha256="0" * 64, code="surge 0.1.0+abc")
    assert decode(spec.encode(), RunSpec) == spec
    piece = SectorForecast(hour=0, sector=2, eta=0.5, nodes=np.array([3, 7], np.int32), rho=np.array([0.25, 0.75]),
                           delta=np.array([1.0, 0.0]), beta=rng.random(5))
    back = decode(piece.encode(), SectorForecast)
    assert back.nodes.dtype == np.int32 and np.array_equal(back.nodes, piece.nodes) and np.array_equal(back.beta, piece.beta)
    drops = decode(Dropoffs(hour=1, delta=rng.random(40)).encode(), Dropoffs)
    assert drops.delta.shape == (40,) and drops.hour == 1
    for msg in (Control(t=3, agent=2, control=-1, epoch=0, by="base", plan_s=0.25), Stop(t=9, epoch=0)):
        assert decode(msg.encode(), type(msg)) == msg
    turn = decode(Turn(t=3, agent=2, deps=np.array([0, 1]), controls=np.array([-1, 7]), epoch=0).encode(), Turn)
    assert (turn.t, turn.agent, turn.deps.tolist(), turn.controls.tolist()) == (3, 2, [0, 1], [-1, 7])
    snap = Snapshot(state=b"abc", forecast=fc.encode())
    assert decode(snap.encode(), (Turn, Snapshot)) == snap
    assert decode(Ack(t=4, agent=1).encode(), Ack) == Ack(t=4, agent=1)


@pytest.mark.parametrize(
    ("payload", "message"),
    [
        (b"\xc1", "not msgpack"),
        (msgpack.packb([1, 2]), "expected a map"),
        (msgpack.packb({"v": 99, "kind": "turn", "t": 1, "agent": 0}), "wire version 99"),
        (msgpack.packb({"v": WIRE_VERSION, "kind": "stop", "t": 1}), "kind 'stop', expected turn"),
        (msgpack.packb({"v": WIRE_VERSION, "kind": "turn", "t": 1}), "turn has no field 'agent'"),
        (msgpack.packb({"v": WIRE_VERSION, "kind": "turn", "t": "1", "agent": 0}), "field 't' is str, expected int"),
        (msgpack.packb({"v": WIRE_VERSION, "kind": "turn", "t": True, "agent": 0}), "field 't' is bool, expected int"),
        (msgpack.packb({"v": 3, "kind": "turn", "t": 1, "agent": 0, "deps": b"", "controls": b""}), "wire version 3, expected 4"),
        (msgpack.packb({"v": WIRE_VERSION, "kind": "turn", "t": 1, "agent": 0, "deps": b"", "controls": b""}), "turn has no field 'epoch'"),
    ],
)
def test_bad_messages_name_the_key_and_field(payload: bytes, message: str) -> None:
    with pytest.raises(WireError) as err:
        decode(payload, Turn, "surge/x/turn/0")
    assert str(err.value).startswith("surge/x/turn/0: ") and message in str(err.value)


def test_bad_arrays_are_caught() -> None:
    good = State(t=0, full=True, pos=[1, 2], tau=[0, 0], dest=[-1, -1], new_index=[], new_pickup=[], new_dropoff=[],
                 new_entry=[], picked=[], outstanding=0, base=[1, -1], home=[], epoch=0)
    raw = msgpack.unpackb(good.encode())
    raw["pos"] = b"\x00\x00\x00"
    with pytest.raises(WireError, match="field 'pos': expected int32 bytes"):
        decode(msgpack.packb(raw), State, "k")
    raw["pos"] = np.array([1], dtype="<i4").tobytes()
    with pytest.raises(WireError, match="one entry per taxi"):
        decode(msgpack.packb(raw), State, "k")
    fc = msgpack.unpackb(ForecastMsg(hour=0, eta=np.ones(3), rho=np.ones(4), delta=np.ones(4), beta=np.ones((3, 3))).encode())
    fc["beta"]["shape"] = [3, 4]
    with pytest.raises(WireError, match=r"field 'beta': shape \[3, 4\] does not match 72 bytes"):
        decode(msgpack.packb(fc), ForecastMsg, "k")


def test_state_deltas_rebuild_every_observation(synthetic_scenario) -> None:
    import datetime as dt

    city, world = synthetic_scenario.city, synthetic_scenario.world
    sim = FleetSim(city, episode_requests(world, dt.date(2022, 11, 17), 19, 15), initial_positions(city, 20, 0))
    view, previous, sizes = StateView(), None, []
    for _ in range(15):
        obs = sim.observe()
        msg = decode(state_message(obs, previous, greedy_controls(city, obs)).encode(), State)
        assert view.apply(msg)
        assert np.array_equal(view.base, greedy_controls(city, obs))
        for name in ("pos", "tau", "dest", "req_index", "req_pickup", "req_dropoff", "req_entry"):
            assert np.array_equal(getattr(view.obs, name), getattr(obs, name)), name
        sizes.append(len(msg.new_index))
        previous = obs.req_index
        sim.step(greedy_controls(city, obs))
    assert sum(sizes[1:]) < 15 * len(obs.req_index)  # deltas, not the whole list every minute
    now = sim.observe()
    gap = state_message(now, None, greedy_controls(city, now))
    later = StateView()
    assert not later.apply(decode(state_message(now, previous, greedy_controls(city, now)).encode(), State))  # a delta needs a base
    assert later.apply(gap) and later.obs.t == sim.observe().t


def test_forecast_request_checks_its_time() -> None:
    req = ForecastRequest(hour=2, when="2022-11-17T21:00:00")
    assert decode(req.encode(), ForecastRequest) == req
    bad = msgpack.unpackb(req.encode())
    bad["when"] = "yesterday"
    with pytest.raises(WireError, match="k: field 'when': 'yesterday' is not an ISO date and time"):
        decode(msgpack.packb(bad), ForecastRequest, "k")


def test_keys_and_ids() -> None:
    k = Keys("run-1")
    assert k.turn(3) == "surge/run-1/turn/3" and Keys.agent_of(k.control(12)) == 12 and Keys.agent_of(k.state) is None
    with pytest.raises(ConfigError, match="run name 'a/b'"):
        Keys("a/b")
    assert parse_ids("0-3,7,2") == [0, 1, 2, 3, 7]
    with pytest.raises(ConfigError, match="'x' is not N or N-M"):
        parse_ids("1,x")


def test_session_settings(capsys: pytest.CaptureFixture) -> None:
    p = argparse.ArgumentParser()
    add_session_args(p)
    assert session_args(p.parse_args(["--insecure"])).connect == [DEFAULT_ENDPOINT]
    assert capsys.readouterr().err.strip() == f"surge: warning: {INSECURE_WARNING}"
    args = session_args(p.parse_args(["--insecure", "--mode", "peer", "-l", "tcp/127.0.0.1:7000"]))
    assert args.mode == "peer" and args.listen == ["tcp/127.0.0.1:7000"] and args.connect == []
    conf = args.zenoh_config()
    assert '"peer"' in conf.get_json("mode") and conf.get_json("scouting/multicast/enabled") == "false"
    with pytest.raises(ConfigError, match="endpoint '7447'"):
        SessionArgs(connect=["7447"])
    with pytest.raises(ConfigError, match="zenoh config /nonexistent.json5: no such file"):
        SessionArgs(config="/nonexistent.json5").zenoh_config()


def test_secured_session_settings(tmp_path) -> None:
    from bus.certs import make_certs

    p = argparse.ArgumentParser()
    add_session_args(p)
    with pytest.raises(ConfigError, match="pass --certs DIR .* or --insecure"):
        session_args(p.parse_args([]))
    with pytest.raises(ConfigError, match="--certs and --insecure: choose one"):
        session_args(p.parse_args(["--certs", str(tmp_path), "--insecure"]))
    with pytest.raises(ConfigError, match=f"--certs {tmp_path / 'none'}: no such directory"):
        session_args(p.parse_args(["--certs", str(tmp_path / "none")]), identity="coordinator")
    certs = tmp_path / "c"
    make_certs(certs, 2)
    client = session_args(p.parse_args(["--certs", str(certs)]), identity="taxi-1")
    assert client.connect == [DEFAULT_TLS_ENDPOINT]
    tls = client.overrides()["transport/link/tls"]
    assert tls == {"root_ca_certificate": str(certs / "ca.pem"), "enable_mtls": True,
                   "connect_certificate": str(certs / "taxi-1.pem"), "connect_private_key": str(certs / "taxi-1.key")}
    assert client.overrides()["transport/link/protocols"] == ["tls"] and "access_control" not in client.overrides()
    with pytest.raises(ConfigError, match="credentials of taxi-2: .*taxi-2.pem: no such file"):
        client.as_identity("taxi-2").overrides()
    router = session_args(p.parse_args(["--certs", str(certs), "--mode", "router"]), identity="router", run="r")
    conf = router.overrides()
    assert router.listen == [DEFAULT_TLS_ENDPOINT] and conf["transport/link/tls"]["listen_certificate"] == str(certs / "router.pem")
    assert conf["access_control"]["default_permission"] == "deny"
    assert '"deny"' in router.zenoh_config().get_json("access_control/default_permission")
    with pytest.raises(ConfigError, match="endpoint 'tcp/127.0.0.1:1': a secured bus .* runs over tls/ endpoints"):
        session_args(p.parse_args(["--certs", str(certs), "-e", "tcp/127.0.0.1:1"]))
    with pytest.raises(ConfigError, match="use --mode client"):
        session_args(p.parse_args(["--certs", str(certs), "--mode", "peer"]))


def test_agent_processes_do_not_import_torch() -> None:
    code = "import sys, agents.taxi, city.scenario, bus.router; print(sorted(m for m in ('torch', 'sentence_transformers') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
