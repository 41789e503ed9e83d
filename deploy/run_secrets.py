"""A run's secrets: Zenoh mTLS identities + ACL, and the MAVLink signing keys.

Made fresh for every `enclose run` in `<run dir>/credentials/` (0700, files 0600); with
`--insecure` nothing is made and every process runs unauthenticated and unsigned.
`enclose keys OUT_DIR` makes the same set for a swarm spread over hosts.

MAVLink: a random run secret (`mavlink-secret.bin`) goes to the simulator alone, which
derives every vehicle's key from it (agents.mavlink.signing.vehicle_key); each agent gets
only its own vehicle's key (`<name>.mavlink-key.bin`), so an agent's key signs for its
vehicle and no other.  `enclose vehicle-key SECRET SYSID` prints a vehicle's passphrase
for a ground station (docs/sim.md).  On one host every process runs as the same user and
could read the folder; the separation holds between hosts (each gets its processes'
files) or with a user per process.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.mavlink.signing import (
    load_key,
    vehicle_key,
    vehicle_passphrase,
    write_key,
    write_raw_key,
)
from agents.scenario.file import load_scenario
from deploy.forked import call_forked
from transport.credentials import Identity, identity_file, make_credentials
from transport.errors import ConfigError
from transport.keys import SwarmKeys

log = logging.getLogger("enclose.secrets")
MAVLINK_SECRET_FILE = "mavlink-secret.bin"


def signing_key_file(cred_dir: Path, name: str) -> Path:
    """Where agent `name`'s vehicle key is (follower-<i>, target-<j>)."""
    return cred_dir / f"{name}.mavlink-key.bin"


def write_mavlink_keys(cred_dir: Path, n: int, m: int) -> None:
    """A fresh run secret, and each agent's vehicle key derived from it: follower i flies
    vehicle i (sysid i+1), target j vehicle n+j (sysid n+j+1)."""
    secret = write_key(cred_dir / MAVLINK_SECRET_FILE)
    agents = [(f"follower-{i}", i) for i in range(n)] + [(f"target-{j}", n + j) for j in range(m)]
    for name, vehicle in agents:
        write_raw_key(signing_key_file(cred_dir, name), vehicle_key(secret, vehicle + 1))


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
        write_mavlink_keys(cred_dir, n, m)
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
        """Command-line arguments that give process `name` its credentials and what it
        signs with: the simulator the run secret, an agent its own vehicle's key."""
        if self.cred_dir is None:
            return []
        out = ["--credentials", str(identity_file(self.cred_dir, name))]
        if name == "sim":
            out += ["--signing-secret", str(self.cred_dir / MAVLINK_SECRET_FILE)]
        elif name.startswith(("follower-", "target-")):
            out += ["--signing-key", str(signing_key_file(self.cred_dir, name))]
        return out


def register(sub: Any) -> None:
    p = sub.add_parser("keys", help="make a swarm's credentials (for processes on several hosts)")
    p.add_argument("out_dir", type=Path, help="directory to create (0700)")
    p.add_argument("scenario", nargs="?", default=None, help="scenario (default: paper)")
    p.add_argument("--swarm", default="enclose", help="swarm name on the bus (key prefix)")
    p.add_argument("--routers", type=int, default=0, metavar="K",
                   help="also certificates router-0..router-K-1, one per host (enclose host)")
    p.set_defaults(func=_keys_main)
    v = sub.add_parser("vehicle-key", help="a vehicle's MAVLink signing passphrase, for a "
                       "ground station (MAVProxy: `signing key <passphrase>`)")
    v.add_argument("secret", type=Path,
                   help=f"the run secret ({MAVLINK_SECRET_FILE}) or the folder holding it")
    v.add_argument("sysid", type=int, help="the vehicle's MAVLink system id (vehicle index + 1)")
    v.add_argument("--out", type=Path, default=None, metavar="FILE",
                   help="also write the raw 32-byte key to FILE (0600), for --signing-key")
    v.set_defaults(func=_vehicle_key_main)


def _keys_main(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    keys = SwarmKeys(args.swarm)
    out = make_credentials(args.out_dir, keys, scenario.n, scenario.m, keep_ca_key=True,
                           n_routers=args.routers)
    write_mavlink_keys(out, scenario.n, scenario.m)
    print(f"credentials for swarm {keys.swarm} ({scenario.n} followers, {scenario.m} targets) "
          f"in {out}: copy ca.pem, acl.json and <name>.{{json,pem,key,mavlink-key.bin}} to the "
          f"host of process <name>, pass --credentials <name>.json and --signing-key "
          f"<name>.mavlink-key.bin; {MAVLINK_SECRET_FILE} only to the simulator's host "
          "(--signing-secret); keep ca.key offline")
    return 0


def _vehicle_key_main(args: argparse.Namespace) -> int:
    path = args.secret / MAVLINK_SECRET_FILE if args.secret.is_dir() else args.secret
    secret = load_key(path)
    if not 1 <= args.sysid <= 255:
        raise ConfigError("sysid", f"a MAVLink system id is 1..255, got {args.sysid}")
    if args.out is not None:
        write_raw_key(args.out, vehicle_key(secret, args.sysid))
    print(vehicle_passphrase(secret, args.sysid))
    return 0
