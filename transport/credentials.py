"""A swarm's Zenoh credentials: a private CA, one mTLS certificate per process, the ACL.

Why mutual TLS and not Zenoh's user/password: measured with Zenoh 1.10 in peer mode
(notes/security.md), usrpwd authenticates only the side that *opens* a link; the side
that accepted it never learns the other's user name, so on half the links of a peer
mesh an ACL subject by user name matches nothing, and per-process rights cannot be
enforced (a forged put from an accepting peer arrives).  With mTLS both ends present a
certificate signed by the swarm's CA, every peer knows every link's common name, and
each peer enforces the same ACL on its own ingress (peers enforce only their own rules).

Layout of a credential directory (0700; every file 0600):
    ca.pem                       the swarm's CA certificate (trust anchor)
    ca.key                       its private key: only `enclose keys` keeps it (to add hosts)
    acl.json                     the `access_control` section every peer loads
    <name>.pem / <name>.key      certificate (common name = <name>) and key of one process
    <name>.json                  identity file given to that process (`--credentials`)
Names are process names: launcher, sim, recorder, follower-<i>, target-<j>.
"""

from __future__ import annotations

import datetime
import json
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from agents.errors import ConfigError
from transport.access import access_control, process_names
from transport.keys import SwarmKeys, validate_name

VALID_DAYS = 30
_PRIVATE = 0o600


@dataclass(frozen=True)
class Identity:
    """What one process needs for an authenticated session: its files, all absolute."""

    name: str
    ca_path: str
    cert_path: str
    key_path: str
    acl_path: str

    @classmethod
    def load(cls, identity_file: str | Path) -> Identity:
        """Read `<name>.json`; relative paths in it are relative to its directory."""
        path = Path(identity_file)
        try:
            raw = json.loads(path.read_text())
            base = path.parent
            ident = cls(validate_name(raw["name"], "credentials.name"),
                        *(str((base / raw[k]).resolve()) for k in ("ca", "cert", "key", "acl")))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ConfigError("credentials", f"{path}: {exc}") from exc
        for field in ("ca_path", "cert_path", "key_path", "acl_path"):
            if not Path(getattr(ident, field)).is_file():
                raise ConfigError(f"credentials.{field}", f"{getattr(ident, field)} is missing")
        return ident

    def acl(self) -> dict[str, object]:
        data: dict[str, object] = json.loads(Path(self.acl_path).read_text())
        return data


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
                     keep_ca_key: bool = False, n_routers: int = 0) -> Path:
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
    add_identities(out_dir, ca_key, ca_cert, process_names(n_followers, n_targets, n_routers))
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


def identity_file(cred_dir: Path, name: str) -> Path:
    return cred_dir / f"{name}.json"
