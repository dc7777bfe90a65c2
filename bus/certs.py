"""Credentials of a fleet: one certificate authority, and a certificate per role and per taxi.

Every process on a secured bus holds a certificate signed by the fleet's CA,
and the router admits only those (mutual TLS).  The router then knows each
session's common name, which the access-control rules of
:mod:`bus.access` are written against: ``router``, ``coordinator``,
``predictor``, ``observer`` (read-only: ``surge watch``) and ``taxi-<i>``.

Keys are ECDSA P-256 in unencrypted PKCS#8 PEM files of mode 0600 (zenoh
reads them at start-up; it cannot prompt for a pass phrase).  The CA's key
is written next to its certificate so more credentials can be issued; it
is needed on no fleet host and should be kept off them.

Before a process connects it checks its own credentials
(:func:`check_credentials`), so that an expired certificate, one from
another CA, or another role's certificate is one line naming what is wrong,
rather than zenoh's "unable to connect" that looks like a missing router.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path

from city.errors import ConfigError

#: The roles that are not taxis, each with one certificate.
ROLES = ("router", "coordinator", "predictor", "observer")
#: Addresses the router's certificate is valid for unless told otherwise: loopback.
DEFAULT_HOSTS = ("127.0.0.1", "localhost")
MANIFEST = "fleet.json"
MANIFEST_SCHEMA = "surge.certs/1"


def taxi_name(index: int) -> str:
    """The common name of taxi ``index``'s certificate."""
    return f"taxi-{index}"


@dataclass(frozen=True)
class Identity:
    """The three files a process needs to join a secured bus as ``name``."""

    name: str
    ca: Path
    cert: Path
    key: Path

    def check(self) -> "Identity":
        """Raise :class:`ConfigError` naming the first missing file."""
        for path in (self.ca, self.cert, self.key):
            if not path.is_file():
                raise ConfigError(f"credentials of {self.name}: {path}: no such file (make them with `surge certs`)")
        return self


def role_of(common_name: str) -> str | None:
    """The role a certificate's common name claims (``taxi`` for ``taxi-<i>``), or ``None`` for no role of surge."""
    if re.fullmatch(r"taxi-(0|[1-9][0-9]*)", common_name):
        return "taxi"
    return common_name if common_name in ROLES else None


def check_credentials(ident: Identity, now: dt.datetime | None = None) -> None:
    """Raise :class:`ConfigError`, in one line, if ``ident``'s certificate cannot get it onto the bus as ``ident.name``.

    Checked in this order: the files parse; the CA and the certificate are
    within their validity; the certificate was signed by the CA given
    (``ca.pem`` of the same directory); its common name is ``ident.name``
    (the role the router grants is the common name's); the key is the
    certificate's.
    """
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization
    from cryptography.x509.oid import NameOID

    who = f"credentials of {ident.name}"
    ident.check()
    try:
        ca = x509.load_pem_x509_certificate(ident.ca.read_bytes())
    except ValueError:
        raise ConfigError(f"{who}: {ident.ca} is not a PEM certificate") from None
    try:
        cert = x509.load_pem_x509_certificate(ident.cert.read_bytes())
    except ValueError:
        raise ConfigError(f"{who}: {ident.cert} is not a PEM certificate") from None
    now = now or dt.datetime.now(dt.timezone.utc)
    for path, c in ((ident.ca, ca), (ident.cert, cert)):
        if now > c.not_valid_after_utc:
            raise ConfigError(f"{who}: {path} expired on {c.not_valid_after_utc:%Y-%m-%d %H:%M} UTC; make new credentials with "
                              f"`surge certs` (or renew them with the fleet's CA)")
        if now < c.not_valid_before_utc:
            raise ConfigError(f"{who}: {path} is not valid until {c.not_valid_before_utc:%Y-%m-%d %H:%M} UTC; "
                              f"check this host's clock")
    try:
        cert.verify_directly_issued_by(ca)
    except Exception:  # cryptography raises ValueError, TypeError or InvalidSignature
        raise ConfigError(f"{who}: {ident.cert} was not issued by the CA in {ident.ca} (its issuer is "
                          f"'{cert.issuer.rfc4514_string()}'): the router admits only certificates of the fleet's CA; use "
                          f"the certificate made with that CA, or that CA's ca.pem") from None
    names = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    cn = str(names[0].value) if names else ""
    if cn != ident.name:
        claimed = role_of(cn)
        what = f"role {claimed!r}" if claimed == cn else (f"role {claimed!r} as {cn!r}" if claimed else "no role of surge")
        raise ConfigError(f"{who}: {ident.cert} has common name {cn!r}, which claims {what}, not {ident.name!r}: the router "
                          f"grants each session its common name's rights; give this process {ident.name}'s own certificate")
    try:
        key = serialization.load_pem_private_key(ident.key.read_bytes(), password=None)
    except (ValueError, TypeError):
        raise ConfigError(f"{who}: {ident.key} is not an unencrypted PEM private key") from None
    if key.public_key().public_bytes(serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo) != \
            cert.public_key().public_bytes(serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo):
        raise ConfigError(f"{who}: {ident.key} is not the key of {ident.cert}")


def identity(certs_dir: str | Path, name: str) -> Identity:
    """The credentials of ``name`` in a directory written by :func:`make_certs`."""
    d = Path(certs_dir)
    if not d.is_dir():
        raise ConfigError(f"--certs {d}: no such directory (make one with `surge certs --out {d} --taxis N`)")
    return Identity(name=name, ca=d / "ca.pem", cert=d / f"{name}.pem", key=d / f"{name}.key").check()


def fleet_size(certs_dir: str | Path) -> int:
    """The number of taxis the directory's credentials were made for (from its manifest)."""
    path = Path(certs_dir) / MANIFEST
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file (make the directory with `surge certs`)") from None
    except ValueError as exc:
        raise ConfigError(f"{path}: not JSON ({exc})") from None
    taxis = doc.get("taxis") if isinstance(doc, dict) else None
    if doc.get("schema") != MANIFEST_SCHEMA or not isinstance(taxis, int) or isinstance(taxis, bool) or taxis < 1:
        raise ConfigError(f"{path}: expected a {MANIFEST_SCHEMA} manifest with a positive 'taxis' count")
    return taxis


def _private_key():
    from cryptography.hazmat.primitives.asymmetric import ec

    return ec.generate_private_key(ec.SECP256R1())


def _write(path: Path, data: bytes, mode: int) -> None:
    """Write a new file created with ``mode`` (never a moment with wider permissions)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    os.chmod(path, mode)  # the umask may have narrowed it further; make it exact


def _san(hosts: list[str]):
    from cryptography import x509

    names = []
    for h in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            names.append(x509.DNSName(h))
    return x509.SubjectAlternativeName(names)


def make_certs(out: str | Path, taxis: int, hosts: list[str] | None = None, days: int = 365) -> list[Path]:
    """Write a CA, the role certificates and ``taxis`` taxi certificates to ``out``; the files written.

    ``hosts`` are the names and addresses clients reach the router by (its
    certificate is checked against them); loopback by default.  ``out`` may
    exist but must not already hold any of the files.
    """
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    if taxis < 1:
        raise ConfigError(f"--taxis {taxis}: a fleet needs at least one taxi")
    if days < 1:
        raise ConfigError(f"--days {days}: certificates must be valid for at least a day")
    hosts = list(hosts or DEFAULT_HOSTS)
    d = Path(out)
    names = [*ROLES, *(taxi_name(i) for i in range(taxis))]
    targets = [d / "ca.pem", d / "ca.key", d / MANIFEST, *(d / f"{n}{ext}" for n in names for ext in (".pem", ".key"))]
    clash = next((p for p in targets if p.exists()), None)
    if clash is not None:
        raise ConfigError(f"{clash} already exists: choose an empty --out directory")
    d.mkdir(parents=True, exist_ok=True)

    now = dt.datetime.now(dt.timezone.utc) - dt.timedelta(minutes=5)
    until = now + dt.timedelta(days=days)
    pem = serialization.Encoding.PEM
    pkcs8 = dict(encoding=pem, format=serialization.PrivateFormat.PKCS8, encryption_algorithm=serialization.NoEncryption())

    ca_key = _private_key()
    ca_name = x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, "surge"),
                         x509.NameAttribute(NameOID.COMMON_NAME, "surge fleet CA")])
    ca_ski = x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key())
    ca = (
        x509.CertificateBuilder().subject_name(ca_name).issuer_name(ca_name).public_key(ca_key.public_key())
        .serial_number(x509.random_serial_number()).not_valid_before(now).not_valid_after(until)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(x509.KeyUsage(digital_signature=False, content_commitment=False, key_encipherment=False,
                                     data_encipherment=False, key_agreement=False, key_cert_sign=True, crl_sign=True,
                                     encipher_only=False, decipher_only=False), critical=True)
        .add_extension(ca_ski, critical=False)
        .sign(ca_key, hashes.SHA256())
    )
    _write(d / "ca.pem", ca.public_bytes(pem), 0o644)
    _write(d / "ca.key", ca_key.private_bytes(**pkcs8), 0o600)
    written = [d / "ca.pem", d / "ca.key"]

    for name in names:
        key = _private_key()
        server = name == "router"
        cert = (
            x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, "surge"),
                                     x509.NameAttribute(NameOID.COMMON_NAME, name)]))
            .issuer_name(ca_name).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(now).not_valid_after(until)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=False, key_encipherment=False,
                                         data_encipherment=False, key_agreement=False, key_cert_sign=False, crl_sign=False,
                                         encipher_only=False, decipher_only=False), critical=True)
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH if server else ExtendedKeyUsageOID.CLIENT_AUTH]),
                           critical=False)
            .add_extension(_san(hosts if server else [name]), critical=False)
            .add_extension(x509.AuthorityKeyIdentifier.from_issuer_subject_key_identifier(ca_ski), critical=False)
            .sign(ca_key, hashes.SHA256())
        )
        _write(d / f"{name}.pem", cert.public_bytes(pem), 0o644)
        _write(d / f"{name}.key", key.private_bytes(**pkcs8), 0o600)
        written += [d / f"{name}.pem", d / f"{name}.key"]
    manifest = {"schema": MANIFEST_SCHEMA, "taxis": taxis, "router_hosts": hosts, "not_after": until.isoformat(timespec="seconds")}
    _write(d / MANIFEST, (json.dumps(manifest, indent=1) + "\n").encode(), 0o644)
    return [*written, d / MANIFEST]
