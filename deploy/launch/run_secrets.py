"""A run's secrets: Zenoh mTLS identities + ACL, and the MAVLink signing key.

Made fresh for every `enclose run` in `<run dir>/credentials/` (0700, files 0600); with
`--insecure` nothing is made and every process runs unauthenticated and unsigned.
`enclose keys OUT_DIR` makes the same set for a swarm spread over hosts, split into a
folder per host (deploy.hosts.host_keys).

MAVLink: a random run secret (`mavlink-secret.bin`) goes to the simulator alone, which
derives every vehicle's key from it (agents.mavlink.signing.vehicle_key); each agent gets
only its own vehicle's key (`<name>.mavlink-key.bin`), so an agent's key signs for its
vehicle and no other.  `enclose vehicle-key SECRET SYSID` prints a vehicle's passphrase
for a ground station (docs/sim.md).  On one host every process runs as the same user and
could read the folder; the separation holds between hosts (each gets its processes'
files) or with a user per process.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from agents.mavlink.signing_keys import agent_of_vehicle, vehicle_key, write_key, write_raw_key
from deploy.procs.forked import call_forked
from transport.credentials import Identity, identity_file, make_credentials
from transport.key_exprs import SwarmKeys

log = logging.getLogger("enclose.secrets")
MAVLINK_SECRET_FILE = "mavlink-secret.bin"


def signing_key_file(cred_dir: Path, name: str) -> Path:
    """Where agent `name`'s vehicle key is (follower-<i>, target-<j>)."""
    return cred_dir / f"{name}.mavlink-key.bin"


def write_mavlink_keys(cred_dir: Path, n: int, m: int) -> None:
    """The MAVLink key material of a swarm of n followers and m targets into `cred_dir`: a
    fresh run secret, and each agent's vehicle key derived from it."""
    secret = write_key(cred_dir / MAVLINK_SECRET_FILE)
    for sysid in range(1, n + m + 1):
        path = signing_key_file(cred_dir, agent_of_vehicle(sysid, n))
        write_raw_key(path, vehicle_key(secret, sysid))


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
        it forks (deploy.procs.forked)."""
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
