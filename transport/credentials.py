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

import json
from dataclasses import dataclass
from pathlib import Path

from errors import ConfigError
from transport.access import process_names
from transport.key_exprs import SwarmKeys, validate_name


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


def make_credentials(out_dir: Path, keys: SwarmKeys, n_followers: int, n_targets: int,
                     keep_ca_key: bool = False, n_routers: int = 0) -> Path:
    """Generate a fresh CA, a certificate per process and the ACL into `out_dir`.

    `cryptography` is imported here, not by the processes that only load an Identity."""
    from transport import credential_gen

    names = process_names(n_followers, n_targets, n_routers)
    return credential_gen.make_credentials(out_dir, keys, n_followers, n_targets, names,
                                           keep_ca_key, n_routers)


def identity_file(cred_dir: Path, name: str) -> Path:
    return cred_dir / f"{name}.json"
