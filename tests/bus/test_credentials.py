"""Credentials an operator can act on: each bad certificate is its own one line before any connection, and the router logs
the handshakes it refuses.

The bad certificates are real ones, signed with the fleet's CA (or another fleet's), as an operator could end up holding.
"""

from __future__ import annotations

import datetime as dt
import json
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bus.certs import check_credentials, identity, make_certs
from bus.router import free_tcp_port, wait_for_tcp
from city.errors import ConfigError
from coordinator.cli import main

CLI = [sys.executable, "-m", "coordinator.cli"]


def _issue(ca_dir: Path, out: Path, name: str, *, days: tuple[float, float]) -> None:
    """Write ``out/<name>.pem`` and ``.key``: a client certificate for ``name`` signed by ``ca_dir``'s CA, valid ``days`` from now."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    ca = x509.load_pem_x509_certificate((ca_dir / "ca.pem").read_bytes())
    ca_key = serialization.load_pem_private_key((ca_dir / "ca.key").read_bytes(), password=None)
    key = ec.generate_private_key(ec.SECP256R1())
    now = dt.datetime.now(dt.timezone.utc)
    cert = (x509.CertificateBuilder().subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
            .issuer_name(ca.subject).public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now + dt.timedelta(days=days[0])).not_valid_after(now + dt.timedelta(days=days[1]))
            .sign(ca_key, hashes.SHA256()))  # type: ignore[arg-type]
    (out / f"{name}.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    (out / f"{name}.key").write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                                        serialization.NoEncryption()))


@pytest.fixture(scope="module")
def creds(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The fleet's credentials, another fleet's, and three directories whose taxi-0 certificate is wrong in one way each."""
    d = tmp_path_factory.mktemp("creds")
    good, rogue = d / "good", d / "rogue"
    make_certs(good, 2)
    make_certs(rogue, 2)
    bad = {}
    for case in ("expired", "other-ca", "other-role"):
        bad[case] = d / case
        bad[case].mkdir()
        for f in ("ca.pem", "fleet.json", "taxi-1.pem", "taxi-1.key"):
            shutil.copy(good / f, bad[case] / f)
    _issue(good, bad["expired"], "taxi-0", days=(-30, -1))
    for ext in (".pem", ".key"):
        shutil.copy(rogue / f"taxi-0{ext}", bad["other-ca"] / f"taxi-0{ext}")
        shutil.copy(good / f"coordinator{ext}", bad["other-role"] / f"taxi-0{ext}")
    return {"good": good, "rogue": rogue, **bad}


@pytest.mark.parametrize(("case", "says"), [
    ("expired", r"credentials of taxi-0: .*/expired/taxi-0\.pem expired on 20\d\d-\d\d-\d\d \d\d:\d\d UTC; make new credentials"),
    ("other-ca", r"credentials of taxi-0: .*/other-ca/taxi-0\.pem was not issued by the CA in .*/other-ca/ca\.pem "),
    ("other-role", r"credentials of taxi-0: .*/other-role/taxi-0\.pem has common name 'coordinator', which claims role "
                   r"'coordinator', not 'taxi-0'"),
])
def test_a_bad_certificate_is_one_line_of_its_own_before_connecting(creds: dict[str, Path], case: str, says: str,
                                                                     capsys: pytest.CaptureFixture) -> None:
    """No router listens on the endpoint: the check comes before any connection, so the line is about the certificate."""
    endpoint = f"tls/127.0.0.1:{free_tcp_port()}"
    assert main(["agents", "--run", "r", "--ids", "0", "--connect", endpoint, "--certs", str(creds[case])]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Unable to connect" not in err[0], err
    assert re.search(says, err[0]), err[0]
    check_credentials(identity(creds[case], "taxi-1"))  # the same directory's good certificate passes


def test_the_checks_pass_good_credentials_and_tell_a_key_of_another_certificate(creds: dict[str, Path], tmp_path: Path) -> None:
    for name in ("router", "coordinator", "predictor", "taxi-0", "taxi-1"):
        check_credentials(identity(creds["good"], name))
    mixed = tmp_path / "mixed"
    shutil.copytree(creds["good"], mixed)
    shutil.copy(creds["good"] / "taxi-1.key", mixed / "taxi-0.key")
    with pytest.raises(ConfigError, match=r"^credentials of taxi-0: .*/mixed/taxi-0\.key is not the key of .*/mixed/taxi-0\.pem$"):
        check_credentials(identity(mixed, "taxi-0"))


def test_the_router_logs_why_it_refused_a_handshake(creds: dict[str, Path], tmp_path: Path) -> None:
    """An outside client skips surge's own check and connects with an expired certificate, then another CA's: the router's
    log gives zenoh's reason for each (zenoh does not say who)."""
    import zenoh

    port = free_tcp_port()
    endpoint = f"tls/127.0.0.1:{port}"
    log = tmp_path / "router.log"
    with log.open("w") as sink:
        router = subprocess.Popen([*CLI, "router", "--certs", str(creds["good"]), "--listen", endpoint], stderr=sink)
        try:
            wait_for_tcp("127.0.0.1", port, 60)
            for case in ("expired", "other-ca"):
                conf = zenoh.Config()
                tls = {"root_ca_certificate": str(creds["good"] / "ca.pem"), "enable_mtls": True,
                       "connect_certificate": str(creds[case] / "taxi-0.pem"), "connect_private_key": str(creds[case] / "taxi-0.key")}
                for path, value in {"mode": "client", "connect/endpoints": [endpoint], "scouting/multicast/enabled": False,
                                    "transport/link/tls": tls}.items():
                    conf.insert_json5(path, json.dumps(value))
                with pytest.raises(Exception, match="Unable to connect"):
                    zenoh.open(conf)
            time.sleep(0.5)
        finally:
            router.terminate()
            router.wait(10)
    text = log.read_text()
    assert "invalid peer certificate: certificate expired" in text and "invalid peer certificate: BadSignature" in text, text
