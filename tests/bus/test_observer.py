"""The read-only ``observer`` role: its rules from the key scheme, and a real TLS router that refuses all it writes."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from bus.access import access_control, grants
from bus.certs import identity, make_certs
from bus.keys import OBSERVED, OBSERVER, SCHEME
from bus.router import free_tcp_port, wait_for_tcp
from bus.session import SessionArgs, open_session, publisher

CLI = [sys.executable, "-m", "coordinator.cli"]
WRITES = {"put", "delete", "declare_queryable", "reply", "liveliness_token"}


def test_the_observer_reads_what_a_follower_needs_and_writes_nothing() -> None:
    rules = grants(OBSERVER, None, "r")
    ingress = {(m, k) for flow, msgs, k in rules if flow == "ingress" for m in msgs}
    assert not {m for m, _ in ingress} & WRITES
    subscribed = {k for m, k in ingress if m == "declare_subscriber"}
    assert subscribed == {f"surge/r/{k}" for k in OBSERVED} | {"surge/r/dropoffs"}
    assert {k for m, k in ingress if m == "query"} == {"surge/r/spec", "surge/r/snapshot", "surge/r/forecast/*"}
    assert {k for m, k in ingress if m == "declare_liveliness_subscriber"} == {"surge/r/alive/*", "surge/r/coordinator/*"}
    # what only the coordinator may read stays its own: proposed controls, acks, the predictor
    assert not any(k.split("/")[2] in ("control", "ack", "predictor") for _, k in ingress)
    acl = access_control(2, "r")
    assert {"id": OBSERVER, "cert_common_names": [OBSERVER]} in acl["subjects"]


def test_surge_certs_makes_the_observer_certificate(tmp_path: Path) -> None:
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    make_certs(tmp_path, 1)
    cert = x509.load_pem_x509_certificate(identity(tmp_path, OBSERVER).cert.read_bytes())
    assert cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == OBSERVER


@pytest.fixture()
def router(tmp_path: Path):
    certs = tmp_path / "certs"
    make_certs(certs, 2)
    port = free_tcp_port()
    endpoint = f"tls/127.0.0.1:{port}"
    proc = subprocess.Popen([*CLI, "router", "--certs", str(certs), "--listen", endpoint, "--run", "r"], stderr=subprocess.DEVNULL)
    try:
        wait_for_tcp("127.0.0.1", port, 60)
        yield SessionArgs(mode="client", connect=[endpoint], certs=str(certs))
    finally:
        proc.terminate()
        proc.wait(10)


def test_on_a_secured_bus_the_observer_follows_key_by_key_and_cannot_write(router: SessionArgs) -> None:
    """A wildcard subscription gets nothing; the observed keys get the coordinator's samples; every write is dropped."""
    got: dict[str, list[str]] = {"wildcard": [], "observed": [], "coordinator": [], "taxi-0": []}
    with (open_session(router.as_identity(OBSERVER)) as lone, open_session(router.as_identity(OBSERVER)) as obs,
          open_session(router.as_identity(OBSERVER)) as forger, open_session(router.as_identity("coordinator")) as coord, open_session(router.as_identity("taxi-0")) as taxi):
        keep = [lone.declare_subscriber("surge/r/**", lambda s: got["wildcard"].append(str(s.key_expr)))]
        keep += [obs.declare_subscriber(f"surge/r/{k}", lambda s: got["observed"].append(f"{s.key_expr} {s.payload.to_bytes().decode()}")) for k in OBSERVED]
        # the coordinator and a taxi listen on every key of the run an observer might try to write
        keep += [coord.declare_subscriber(f"surge/r/{c.name}" + ("/*" if c.indexed else ""),
                                          lambda s: got["coordinator"].append(f"{s.key_expr} {s.payload.to_bytes().decode()}")) for c in SCHEME]
        keep += [taxi.declare_subscriber(f"surge/r/{c.name}" + ("/*" if c.indexed else ""),
                                         lambda s: got["taxi-0"].append(f"{s.key_expr} {s.payload.to_bytes().decode()}")) for c in SCHEME]
        alive = [coord.liveliness().declare_subscriber("surge/r/alive/*", lambda s: got["coordinator"].append(f"token {s.key_expr}")),
                 taxi.liveliness().declare_subscriber("surge/r/coordinator", lambda s: got["taxi-0"].append(f"token {s.key_expr}"))]
        time.sleep(1.5)
        state, commit = publisher(coord, "surge/r/state"), publisher(coord, "surge/r/committed/1")
        forged = [k for c in SCHEME for k in ([f"surge/r/{c.name}/0", f"surge/r/{c.name}/1"] if c.indexed else [f"surge/r/{c.name}"])]
        tokens = [forger.liveliness().declare_token(k) for k in ("surge/r/alive/0", "surge/r/coordinator")]
        queryable = forger.declare_queryable("surge/r/spec", lambda q: q.reply("surge/r/spec", b"forged"))
        for _ in range(3):
            state.put(b"s")
            commit.put(b"c")
            for k in forged:
                forger.put(k, b"forged")
                forger.delete(k)
            time.sleep(0.3)
        time.sleep(1.0)
        answers = [r for r in taxi.get("surge/r/spec", timeout=2.0) if r.ok is not None]
        del tokens, queryable, alive, keep
    assert got["wildcard"] == []
    assert sorted(set(got["observed"])) == ["surge/r/committed/1 c", "surge/r/state s"] and len(got["observed"]) == 6
    # the coordinator hears its own samples (zenoh delivers them locally) and nothing of the observer's
    assert sorted(set(got["coordinator"])) == ["surge/r/committed/1 c", "surge/r/state s"]
    assert sorted(set(got["taxi-0"])) == ["surge/r/committed/1 c", "surge/r/state s"] and len(got["taxi-0"]) == 6
    assert answers == []
