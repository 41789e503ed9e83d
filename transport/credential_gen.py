"""Making a swarm's credentials (transport.credentials): the only module importing `cryptography`.

Kept apart so that the swarm's processes, which only read their identity files, do not
load it (~10 MB of RSS and ~0.1 s of imports each; bench/bench_start.py).
"""

from __future__ import annotations

import datetime
import json
import os
from collections.abc import Iterable
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from transport.access import access_control
from transport.key_exprs import SwarmKeys, validate_name

VALID_DAYS = 30
_PRIVATE = 0o600


def _write_private(path: Path, data: bytes) -> None:
    """Create with 0600 from the start (no window in which another user could read it)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, _PRIVATE)
    with os.fdopen(fd, "wb") as out:
        out.write(data)
    os.chmod(path, _PRIVATE)


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def _cert(name: str, key: ec.EllipticCurvePrivateKey, issuer: x509.Name,
          signer: ec.EllipticCurvePrivateKey, ca: bool) -> x509.Certificate:
    now = datetime.datetime.now(datetime.UTC)
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
    builder = (x509.CertificateBuilder().subject_name(subject).issuer_name(issuer)
               .public_key(key.public_key()).serial_number(x509.random_serial_number())
               .not_valid_before(now - datetime.timedelta(minutes=5))
               .not_valid_after(now + datetime.timedelta(days=VALID_DAYS))
               .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True))
    if not ca:
        # Names are not verified on connect (the CN is the process identity, not a host);
        # the SAN only keeps TLS stacks that insist on one happy.
        builder = builder.add_extension(x509.SubjectAlternativeName(
            [x509.DNSName("localhost"), x509.DNSName(name)]), critical=False)
    return builder.sign(signer, hashes.SHA256())


def make_credentials(out_dir: Path, keys: SwarmKeys, n_followers: int, n_targets: int,
                     names: Iterable[str], keep_ca_key: bool = False,
                     n_routers: int = 0) -> Path:
    """Generate a fresh CA, a certificate per process and the ACL into `out_dir`."""
    out_dir.mkdir(parents=True, exist_ok=True)
    os.chmod(out_dir, 0o700)
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"enclose-ca-{keys.swarm}")])
    ca_cert = _cert(f"enclose-ca-{keys.swarm}", ca_key, ca_name, ca_key, ca=True)
    _write_private(out_dir / "ca.pem", ca_cert.public_bytes(serialization.Encoding.PEM))
    if keep_ca_key:
        _write_private(out_dir / "ca.key", _key_pem(ca_key))
    acl = access_control(keys, n_followers, n_targets, n_routers)
    _write_private(out_dir / "acl.json", json.dumps(acl, indent=1).encode())
    add_identities(out_dir, ca_key, ca_cert, names)
    return out_dir


def add_identities(out_dir: Path, ca_key: ec.EllipticCurvePrivateKey, ca_cert: x509.Certificate,
                   names: Iterable[str]) -> None:
    for name in names:
        validate_name(name, "credentials.name")
        key = ec.generate_private_key(ec.SECP256R1())
        cert = _cert(name, key, ca_cert.subject, ca_key, ca=False)
        _write_private(out_dir / f"{name}.key", _key_pem(key))
        _write_private(out_dir / f"{name}.pem", cert.public_bytes(serialization.Encoding.PEM))
        ident = {"name": name, "ca": "ca.pem", "cert": f"{name}.pem", "key": f"{name}.key",
                 "acl": "acl.json"}
        _write_private(out_dir / f"{name}.json", json.dumps(ident, indent=1).encode())

