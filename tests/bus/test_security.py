"""The secured bus: credentials, access rules from the key scheme, and hostile clients against a real TLS router.

The hostile clients (``tests/bus/hostile.py``) use only zenoh and msgpack, as an
outsider would.  Small fleets and few minutes keep this file fast.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Iterator

import pytest

from bus.access import access_control, grants
from bus.certs import identity, make_certs
from bus.keys import SCHEME, TAXI
from bus.router import free_tcp_port, wait_for_tcp
from city.errors import ConfigError
from coordinator.cli import main
from coordinator.fleet import in_process
from coordinator.run_config import FleetConfig

CLI = [sys.executable, "-m", "coordinator.cli"]
HOSTILE = [sys.executable, str(Path(__file__).with_name("hostile.py"))]


def test_certs_command_writes_a_ca_role_and_taxi_certificates(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from cryptography import x509
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    out = tmp_path / "creds"
    assert main(["certs", "--out", str(out), "--taxis", "3", "--host", "10.0.0.7"]) == 0
    text = capsys.readouterr().out
    assert str(out / "ca.pem") in text and str(out / "taxi-2.pem") in text and "mode 0600" in text
    ca = x509.load_pem_x509_certificate((out / "ca.pem").read_bytes())
    for name in ("router", "coordinator", "predictor", "taxi-0", "taxi-1", "taxi-2"):
        ident = identity(out, name)
        cert = x509.load_pem_x509_certificate(ident.cert.read_bytes())
        assert cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == name
        ca.public_key().verify(cert.signature, cert.tbs_certificate_bytes, ec.ECDSA(cert.signature_hash_algorithm))
        assert cert.issuer == ca.subject
        assert ident.key.stat().st_mode & 0o777 == 0o600 and ident.cert.stat().st_mode & 0o077 != 0o077
    router = x509.load_pem_x509_certificate((out / "router.pem").read_bytes())
    assert "10.0.0.7" in str(router.extensions.get_extension_for_class(x509.SubjectAlternativeName).value)
    assert (out / "ca.key").stat().st_mode & 0o777 == 0o600
    assert json.loads((out / "fleet.json").read_text())["taxis"] == 3
    assert main(["certs", "--out", str(out), "--taxis", "3"]) == 2
    assert "already exists: choose an empty --out directory" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="credentials of taxi-3: .*taxi-3.pem: no such file"):
        identity(out, "taxi-3")


def test_every_key_has_one_writer_and_the_rules_follow_the_scheme() -> None:
    acl = access_control(4, "r")
    assert acl["enabled"] and acl["default_permission"] == "deny"
    assert {r["permission"] for r in acl["rules"]} == {"allow"}
    who = {s["id"]: s["cert_common_names"] for s in acl["subjects"]}
    assert all(len(names) == 1 and names[0] == sid for sid, names in who.items())
    rules = {r["id"]: r for r in acl["rules"]}
    granted: dict[str, set] = {}
    for pol in acl["policies"]:
        for rid in pol["rules"]:
            rule = rules[rid]
            for msg in rule["messages"]:
                for k in rule["key_exprs"]:
                    granted.setdefault(f"{rule['flows'][0]} {msg} {k}", set()).update(pol["subjects"])
    writes = {"put", "declare_queryable", "reply", "liveliness_token"}
    for channel in SCHEME:
        keys = [f"surge/r/{channel.name}/{i}" for i in range(4)] if channel.indexed else [f"surge/r/{channel.name}"]
        for i, k in enumerate(keys):
            writers = {s for g, subjects in granted.items() for s in subjects
                       if g.split()[0] == "ingress" and g.split()[1] in writes and g.split()[2] in (k, k.rsplit("/", 1)[0] + "/*")}
            expected = {f"taxi-{i}"} if channel.writer == TAXI else set(channel.writers)
            assert writers == expected, (k, writers)
    assert {c.name: c.writers for c in SCHEME if len(c.writers) > 1} == {"forecast": ("coordinator", "predictor"),
                                                                           "dropoffs": ("coordinator", "predictor")}
    mine = {(flow, msgs, k) for flow, msgs, k in grants(TAXI, 3, "r")}
    assert ("ingress", ("put",), "surge/r/control/3") in mine and ("egress", ("put",), "surge/r/turn/3") in mine
    assert not any(k.endswith("/turn/*") and flow == "egress" for flow, _, k in mine)  # a taxi sees only its own turns


# ------------------------------------------------------------ a real router
@pytest.fixture(scope="module")
def secured(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    """A TLS router with access control for run ``acl``, credentials for 5 taxis, and a rogue CA's."""
    d = tmp_path_factory.mktemp("secured")
    certs, rogue = d / "certs", d / "rogue"
    make_certs(certs, 5)
    make_certs(rogue, 5)
    port = free_tcp_port()
    endpoint = f"tls/127.0.0.1:{port}"
    proc = subprocess.Popen([*CLI, "router", "--certs", str(certs), "--listen", endpoint], stderr=subprocess.PIPE, text=True)
    try:
        assert "mutual TLS" in proc.stderr.readline()
        wait_for_tcp("127.0.0.1", port, 30)
        yield {"endpoint": endpoint, "tcp_endpoint": f"tcp/127.0.0.1:{port}", "certs": str(certs), "rogue": str(rogue), "router": proc}
    finally:
        proc.terminate()
        proc.wait(10)


def test_taxi_3s_certificate_can_do_only_what_taxi_3_does(secured: dict) -> None:
    args = {k: v for k, v in secured.items() if k != "router"}
    proc = subprocess.run([*HOSTILE, "probe", json.dumps({**args, "run": "acl"})], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.splitlines()[-1])
    assert out["connects"] == {"no-cert": False, "plain-tcp": False, "rogue-ca-taxi-3": False, "router-cert": False}
    seen = [tuple(s) for s in out["seen"]]
    # what taxi 3 may do arrives, which shows the observers were listening ...
    assert ("coordinator", "surge/acl/control/3", "taxi-3 on its own key") in seen
    assert ("coordinator", "surge/acl/ack/3", "taxi-3 acks on its own key") in seen
    assert ("coordinator", "surge/acl/alive/3", "token") in seen
    assert ("taxi-0", "surge/acl/state", "the coordinator's state") in seen
    # ... and nothing else: no control/4, ack/4, committed, state, forecast, turn or stop from taxi 3, no alive/4
    # and no coordinator token (taxi-0 watches for one), and no control/3 or ack/3 from any other identity
    assert [s for s in seen if "forged" in s[2] or s[1].endswith(("alive/4", "/coordinator/9"))] == []
    assert len(seen) == 4 and out["coordinator token"] == "seen"
    assert out["answers"] == {"taxi-0 spec": ["coordinator"], "taxi-0 snapshot": ["coordinator"],
                              "coordinator predictor": ["predictor"], "taxi-4 spec": ["coordinator"],
                              "taxi-0 forecast/0": ["coordinator"]}
    assert secured["router"].poll() is None


def _lines(stream, into: list[str]) -> threading.Thread:
    t = threading.Thread(target=lambda: into.extend(iter(stream.readline, "")), daemon=True)
    t.start()
    return t


def test_forged_stays_and_a_fuzz_flood_change_nothing(secured: dict, tmp_path: Path, synthetic_scenario) -> None:
    """Every identity but taxi 3's answers taxi 3's turns with "stay"; 10,000 fuzz messages on every key a taxi may write."""
    pytest.importorskip("numba")
    from agents.rollout import warm_up

    warm_up(synthetic_scenario.city)
    run, out, ep, certs = "attack", tmp_path / "result.json", secured["endpoint"], secured["certs"]
    bus = ["--connect", ep, "--certs", certs]
    coord = subprocess.Popen([*CLI, "coordinator", *bus, "--run", run, "--taxis", "4", "--minutes", "6", "--forecast", "true-rate",
                              "--samples", "50", "--deadline", "60", "--minute-seconds", "1.5", "--join-timeout", "300",
                              "--predictor", "--json", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    predictor = subprocess.Popen([*CLI, "predictor", "serve", *bus, "--run", run, "--forecast", "true-rate"],
                                 stderr=subprocess.DEVNULL, text=True)
    agents = subprocess.Popen([*CLI, "agents", *bus, "--run", run, "--ids", "0-3"], stderr=subprocess.PIPE, text=True)
    procs = [coord, predictor, agents]
    err: list[str] = []
    reader = _lines(coord.stderr, err)
    try:
        deadline = time.monotonic() + 240
        while not any("agents joined" in line for line in err):
            assert coord.poll() is None and time.monotonic() < deadline, "".join(err)
            time.sleep(0.2)
        plan = {"endpoint": ep, "certs": certs, "run": run, "victim": 3, "fuzz": 10_000, "max_s": 120, "seed": 1,
                "attackers": ["coordinator", "predictor", "taxi-0", "taxi-1", "taxi-2", "taxi-4"],
                "fuzzers": ["taxi-0", "taxi-1", "taxi-2", "taxi-3", "taxi-4"]}
        hostile = subprocess.Popen([*HOSTILE, "attack", json.dumps(plan)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        procs.append(hostile)
        assert hostile.stdout.readline().strip() == "fuzzed 10000"
        alive = {p.args[3] if p is not hostile else "hostile": p.poll() is None for p in procs}
        assert all(alive.values()) and secured["router"].poll() is None, alive
        report, hostile_err = hostile.communicate(timeout=180)
        assert hostile.returncode == 0, hostile_err
        assert coord.wait(180) == 0, "".join(err)[-3000:]
        assert agents.wait(60) == 0
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
            p.wait(10)
    reader.join(5)
    attack = json.loads(report.splitlines()[-1])
    assert attack["connects"] == {"no-cert": False, "router-cert": False}
    assert attack["turns_seen"] == {n: 0 for n in plan["attackers"]}  # nobody else sees taxi 3's turns
    assert min(attack["forged"].values()) > 10
    result = json.loads(out.read_text())
    ref = in_process(FleetConfig(taxis=4, minutes=6, options={"forecast": "true-rate", "samples": 50}))
    assert result["fallbacks"] == 0 and result["planned_per_agent"][3] > 0
    assert result["decisions_sha256"] == ref["decisions_sha256"] and result["total_cost"] == ref["total_cost"]
    # every fuzz message on a control key reached the coordinator and was dropped; no forged stay got through the router
    on_controls = sum(n for kind, n in result["rejected_messages"].items() if kind.startswith("control:"))
    assert on_controls + result["stale_messages"] == attack["fuzz_controls"]
    # the well-formed control no taxi has was judged as such (its log line may be one of the kinds past
    # Rejections.MAX_KINDS, which are counted without a word)
    assert any("not one of its controls" in kind for kind in result["rejected_messages"]), result["rejected_messages"]
    log = "".join(err)
    assert "ignored: surge/attack/control/" in log, [x for x in err if "ignored" in x]
    assert log.count("ignored:") <= len(result["rejected_messages"])  # at most one line per kind, not one per message
    assert os.path.getsize(out) > 0


# ------------------------------------------------------ distrust on receipt
def _agent(run: str = "u", me: int = 1):
    """An agent that accepted a 3-taxi spec of the synthetic city, with no bus (messages are handed in)."""
    from agents.rollout import RolloutConfig
    from agents.taxi import AgentConfig, TaxiAgent
    from bus.session import SessionArgs
    from bus.wire import RunSpec
    from city.fingerprint import city_sha256, code_version
    from city.scenario import load_city

    agent = TaxiAgent(AgentConfig(index=me, run=run, bus=SessionArgs(mode="client", connect=["tcp/127.0.0.1:1"])))
    spec = RunSpec(run=run, scenario="synthetic", data_dir=None, city=load_city("synthetic").summary(), taxis=3, minutes=4,
                   policy="surge", rollout={"samples": 4, "horizon": 2}, deadline_s=5.0,
                   city_sha256=city_sha256(load_city("synthetic")), code=code_version())
    agent._accept_spec(spec.encode())
    from bus.checks import Bounds

    agent.bounds = Bounds(taxis=3, nodes=agent.city.n_nodes, sectors=agent.city.n_sectors, minutes=4)
    assert agent.rollout == RolloutConfig(samples=4, horizon=2)
    return agent, spec


def test_an_agent_drops_what_does_not_fit_its_run_and_keeps_going(capsys: pytest.CaptureFixture) -> None:
    import dataclasses

    import numpy as np

    from agents.rollout_inputs import candidate_controls
    from bus.delta import state_message
    from bus.forecast_messages import sector_message
    from bus.session import Inbox
    from bus.wire import Control, Dropoffs, Stop, Turn, WireError, decode
    from city.forecast import Forecast
    from city.sim import Observation

    agent, spec = _agent()
    k = agent.keys
    bad_spec = dataclasses.replace(spec, rollout={"samples": 4, "teleport": True})
    with pytest.raises(WireError, match="field 'rollout' has unknown settings 'teleport'"):
        agent._accept_spec(bad_spec.encode())
    with pytest.raises(WireError, match="has only 1 taxis; this is agent 1"):
        agent._accept_spec(dataclasses.replace(spec, taxis=1).encode())
    n = agent.city.n_nodes
    pos = np.array([0, 5, 9], dtype=np.int32)
    obs = Observation(t=0, pos=pos, tau=np.zeros(3, np.int32), dest=np.full(3, -1, np.int32), req_index=np.zeros(0, np.int64),
                      req_pickup=np.zeros(0, np.int32), req_dropoff=np.zeros(0, np.int32), req_entry=np.zeros(0, np.int32))
    good = state_message(obs, None, np.array([0, 5, 9], dtype=np.int32))
    two = dataclasses.replace(good, pos=pos[:2], tau=good.tau[:2], dest=good.dest[:2], base=good.base[:2])
    off_map = dataclasses.replace(good, pos=np.array([0, n, 9], dtype=np.int32))
    cands = candidate_controls(agent.city, obs, 0).tolist()
    ok, not_a_move = cands[-1], next(v for v in range(n) if v not in cands)
    S = agent.city.n_sectors
    fc = Forecast(eta=np.full(S, 0.5), rho=np.ones(n), delta=np.ones(n), beta=np.full((S, S), 1.0 / S))
    sent = []

    class Out:
        def put(self, payload: bytes) -> None:
            sent.append(decode(payload, Control))

    def turn(t: int, deps: list[int], controls: list[int]) -> bytes:
        return Turn(t=t, agent=1, deps=np.array(deps, np.int32), controls=np.array(controls, np.int32), epoch=0).encode()

    inbox = Inbox()
    for item in [
        ("state", k.state, two.encode()),  # fewer taxis than the run: was an IndexError
        ("state", k.state, off_map.encode()),
        ("state", k.state, good.encode()),
        ("turn", k.turn(1), turn(0, [0], [n])),  # a predecessor's control off the map
        ("turn", k.turn(1), turn(0, [0], [-5])),  # the same kind: counted, not logged again
        ("turn", k.turn(1), turn(0, [2], [ok])),  # agent 2 is no predecessor of agent 1
        ("turn", k.turn(1), turn(7, [], [])),  # not a minute of the episode
        ("turn", k.turn(1), turn(2, [], [])),  # ahead of its state: held, then replaced by the turn of minute 0
        ("stop", k.stop, Stop(t=1, epoch=0).encode()),  # not the run's end: the agent stays
        ("forecast", k.forecast(0), b"\x93\x01\x02"),
        *[("forecast", k.forecast(s), sector_message(fc, agent.city, 0, s).encode()) for s in range(S)],
        ("dropoffs", k.dropoffs, Dropoffs(hour=0, delta=fc.delta).encode()),
        ("turn", k.turn(1), turn(0, [0], [not_a_move])),  # checked when the agent plans: dropped, no control sent
        ("turn", k.turn(1), turn(0, [0], [ok])),
        ("stop", k.stop, Stop(t=4, epoch=0).encode()),
    ]:
        inbox.put(*item)
    agent._loop(None, inbox, Out())
    err = capsys.readouterr().err
    for reason in ("field 'pos' has 2 taxis, the run has 3", f"field 'pos' holds {n}, outside 0..{n - 1}",
                   f"turn/1: field 'controls' holds {n}, outside -1..{n - 1}",
                   f"control {not_a_move} of agent 0 is not one of its controls",
                   "turn/1: field 't' is 7, outside the episode's minutes 0..3", "field 't' is 1, the run ends after minute 4",
                   "forecast"):
        assert reason in err, reason
    assert "holds -5" not in err and "'deps'" not in err  # the same kind as the first: counted, not logged again
    assert agent.rejected.counts["turn: surge/u/turn/N: field Q holds N, outside N.N"] == 3
    assert agent.view.obs is not None and agent.view.obs.t == 0
    assert [(c.t, c.agent) for c in sent] == [(0, 1)] and agent.decisions == 1  # only the good turn was planned


def test_the_coordinator_waits_for_a_good_control_and_survives_bad_queries() -> None:
    from bus.wire import Control
    from coordinator.runtime import Coordinator

    coord = Coordinator(FleetConfig(run="c", taxis=3, minutes=2, options={"forecast": "true-rate", "samples": 4}), progress=False)
    coord.obs = obs = coord.sim.observe()
    k = coord.keys
    from agents.rollout_inputs import candidate_controls

    ok = int(candidate_controls(coord.city, obs, 1)[0])
    want = {(0, 1)}
    for payload in (Control(t=0, agent=1, control=2**40, epoch=0).encode(), Control(t=0, agent=1, control=-5, epoch=0).encode(),
                    Control(t=0, agent=1, control=ok, epoch=0, by="base").encode(), Control(t=0, agent=1, control=ok, epoch=0, plan_s=float("nan")).encode(),
                    b"junk"):
        assert coord._handle(("control", k.control(1), payload), want) is None
    assert coord._handle(("control", k.control(2), Control(t=0, agent=1, control=ok, epoch=0).encode()), want) is None
    assert coord._handle(("alive", k.alive(7), True), want) is None and coord.health.alive == set()

    class Gone:
        def reply(self, *_, **__):
            raise RuntimeError("the querier left")

        def drop(self) -> None:
            pass

    assert coord._handle(("snapshot", k.snapshot, Gone()), want) is None
    got = coord._handle(("control", k.control(1), Control(t=0, agent=1, control=ok, epoch=0).encode()), want)
    assert got is not None and got.control == ok
    kinds = coord.rejected.counts
    assert sum(kinds.values()) == 8 and any("RuntimeError" in kind for kind in kinds)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["coordinator", "--run", "x"], "the bus runs with mutual TLS and access control: pass --certs DIR"),
        (["agents", "--ids", "0"], "pass --certs DIR (make it with `surge certs --out DIR --taxis N`), or --insecure"),
        (["router", "--certs", "/nonexistent"], "--certs /nonexistent: no such directory"),
        (["fleet", "--certs", "/nonexistent", "--insecure"], "--certs and --insecure: choose one"),
        (["predictor", "serve", "--forecast", "true-rate", "--certs", "/nonexistent"], "--certs /nonexistent: no such directory"),
    ],
)
def test_the_bus_is_secured_unless_asked_otherwise(args: list[str], message: str, capsys: pytest.CaptureFixture) -> None:
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_insecure_says_so_in_one_line(tmp_path: Path) -> None:
    proc = subprocess.run([*CLI, "router", "--insecure", "--print-config"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stderr.strip().splitlines() == [
        "surge: warning: --insecure: the bus runs without TLS or access control; anyone who reaches it can steer the fleet"]
    assert "access_control" not in json.loads(proc.stdout)
    make_certs(tmp_path / "c", 2)
    proc = subprocess.run([*CLI, "router", "--certs", str(tmp_path / "c"), "--run", "r1", "--print-config"],
                          capture_output=True, text=True, timeout=60)
    conf = json.loads(proc.stdout)
    assert conf["listen"]["endpoints"] == ["tls/127.0.0.1:7447"] and conf["transport"]["link"]["protocols"] == ["tls"]
    assert {k for r in conf["access_control"]["rules"] for k in r["key_exprs"]} >= {"surge/r1/control/1", "surge/r1/state"}


def test_an_agent_follows_the_highest_run_epoch_and_drops_a_fenced_coordinators_messages(capsys: pytest.CaptureFixture) -> None:
    """Tokens of epochs 5 and then 9: the state, turn and stop of epoch 5 are dropped, and the turn of epoch 9 is answered
    with epoch 9; epoch 5's token going does not count as the coordinator gone."""
    import numpy as np

    from agents.rollout_inputs import candidate_controls
    from bus.delta import state_message
    from bus.forecast_messages import sector_message
    from bus.session import Inbox
    from bus.wire import Control, Dropoffs, Stop, Turn, decode
    from city.forecast import Forecast
    from city.sim import Observation

    agent, _ = _agent(run="e")
    k, n, S = agent.keys, agent.city.n_nodes, agent.city.n_sectors
    obs = Observation(t=0, pos=np.array([0, 5, 9], np.int32), tau=np.zeros(3, np.int32), dest=np.full(3, -1, np.int32),
                      req_index=np.zeros(0, np.int64), req_pickup=np.zeros(0, np.int32), req_dropoff=np.zeros(0, np.int32),
                      req_entry=np.zeros(0, np.int32))
    base = np.array([0, 5, 9], dtype=np.int32)
    fc = Forecast(eta=np.full(S, 0.5), rho=np.ones(n), delta=np.ones(n), beta=np.full((S, S), 1.0 / S))
    ok = int(candidate_controls(agent.city, obs, 0)[-1])
    sent = []

    class Out:
        def put(self, payload: bytes) -> None:
            sent.append(decode(payload, Control))

    def turn(epoch: int) -> bytes:
        return Turn(t=0, agent=1, deps=np.array([0], np.int32), controls=np.array([ok], np.int32), epoch=epoch).encode()

    inbox = Inbox()
    for item in [
        ("coordinator", k.coordinator(5), True),
        ("coordinator", k.coordinator(9), True),  # a takeover
        ("state", k.state, state_message(obs, None, base, 5).encode()),
        ("stop", k.stop, Stop(t=1, epoch=5, reason="the coordinator was stopped (exit 143)").encode()),
        ("state", k.state, state_message(obs, None, base, 9).encode()),
        *[("forecast", k.forecast(s), sector_message(fc, agent.city, 0, s).encode()) for s in range(S)],
        ("dropoffs", k.dropoffs, Dropoffs(hour=0, delta=fc.delta).encode()),
        ("turn", k.turn(1), turn(5)),
        ("turn", k.turn(1), turn(9)),
        ("coordinator", k.coordinator(5), False),  # the fenced coordinator leaves
        ("stop", k.stop, Stop(t=4, epoch=9).encode()),
    ]:
        inbox.put(*item)
    agent._loop(None, inbox, Out())
    err = capsys.readouterr().err
    assert "the coordinator of run epoch 9 took the run over from epoch 5" in err
    for what in ("state", "stop", "turn"):
        assert f"a {what} of run epoch 5, whose coordinator was taken over by epoch 9" in err, what
    assert [(c.t, c.agent, c.epoch) for c in sent] == [(0, 1, 9)] and agent.decisions == 1
    assert agent.epoch == 9 and agent.coordinator_gone is None
