"""A run's secrets: Zenoh mTLS identities + ACL, and the MAVLink signing key.

Made fresh for every `enclose run` in `<run dir>/credentials/` (0700, files 0600); with
`--insecure` nothing is made and every process runs unauthenticated and unsigned.
`enclose keys OUT_DIR` makes the same set for a swarm spread over hosts.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.mavlink.signing import write_key
from agents.scenario.file import load_scenario
from deploy.forked import call_forked
from transport.credentials import Identity, identity_file, make_credentials
from transport.keys import SwarmKeys

log = logging.getLogger("enclose.secrets")
SIGNING_KEY_FILE = "mavlink-signing-key.bin"


@dataclass(frozen=True)
class RunSecrets:
    """Where a run's secrets are; None everywhere for an insecure run."""

    cred_dir: Path | None

    @classmethod
    def make(cls, out: Path, keys: SwarmKeys, n: int, m: int, insecure: bool,
             n_routers: int = 0) -> RunSecrets:
        if insecure:
            log.warning("--insecure: Zenoh is unauthenticated and MAVLink unsigned; any "
                        "process on this machine can join the swarm and command its vehicles")
            return cls(None)
        cred_dir = make_credentials(out / "credentials", keys, n, m, n_routers=n_routers)
        write_key(cred_dir / SIGNING_KEY_FILE)
        return cls(cred_dir)

    @classmethod
    def make_apart(cls, out: Path, keys: SwarmKeys, n: int, m: int, insecure: bool,
                   meanwhile: Callable[[], None]) -> RunSecrets:
        """`make`, in a short-lived fork when secure, while this process runs `meanwhile`:
        `cryptography` (~10 MB) then stays out of the launcher, and of the swarm processes
        it forks (deploy.forked)."""
        if insecure:
            meanwhile()
            return cls.make(out, keys, n, m, insecure)

        def make() -> None:
            cls.make(out, keys, n, m, insecure)

        call_forked(make, "making the run's credentials", meanwhile)
        return cls(out / "credentials")

    def identity(self, name: str) -> Identity | None:
        return None if self.cred_dir is None else Identity.load(identity_file(self.cred_dir, name))

    def args_for(self, name: str) -> list[str]:
        """Command-line arguments that give process `name` its credentials and signing key."""
        if self.cred_dir is None:
            return []
        out = ["--credentials", str(identity_file(self.cred_dir, name))]
        if name == "sim" or name.startswith(("follower-", "target-")):
            out += ["--signing-key", str(self.cred_dir / SIGNING_KEY_FILE)]
        return out


def register(sub: Any) -> None:
    p = sub.add_parser("keys", help="make a swarm's credentials (for processes on several hosts)")
    p.add_argument("out_dir", type=Path, help="directory to create (0700)")
    p.add_argument("scenario", nargs="?", default=None, help="scenario (default: paper)")
    p.add_argument("--swarm", default="enclose", help="swarm name on the bus (key prefix)")
    p.add_argument("--routers", type=int, default=0, metavar="K",
                   help="also certificates router-0..router-K-1, one per host (enclose host)")
    p.set_defaults(func=_keys_main)


def _keys_main(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    keys = SwarmKeys(args.swarm)
    out = make_credentials(args.out_dir, keys, scenario.n, scenario.m, keep_ca_key=True,
                           n_routers=args.routers)
    write_key(out / SIGNING_KEY_FILE)
    print(f"credentials for swarm {keys.swarm} ({scenario.n} followers, {scenario.m} targets) "
          f"in {out}: copy ca.pem, acl.json and <name>.{{json,pem,key}} to the host of process "
          f"<name>, pass --credentials <name>.json; {SIGNING_KEY_FILE} to the vehicles' hosts; "
          "keep ca.key offline")
    return 0
