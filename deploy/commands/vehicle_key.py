"""`enclose vehicle-key SECRET SYSID`: a vehicle's MAVLink signing passphrase, for a ground
station (MAVProxy: `signing key <passphrase>`; docs/sim.md).

Derived from a run's secret (agents.mavlink.signing.vehicle_passphrase): whoever holds the
secret holds every vehicle's key.  `--out FILE` also writes the raw key (0600), the file
`--signing-key` takes.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from agents.mavlink.signing_keys import load_key, vehicle_key, vehicle_passphrase, write_raw_key
from deploy.launch.run_secrets import MAVLINK_SECRET_FILE
from errors import ConfigError


def register(sub: Any) -> None:
    p = sub.add_parser("vehicle-key", help="a vehicle's MAVLink signing passphrase, for a "
                       "ground station (MAVProxy: `signing key <passphrase>`)")
    p.add_argument("secret", type=Path,
                   help=f"the run secret ({MAVLINK_SECRET_FILE}) or the folder holding it")
    p.add_argument("sysid", type=int, help="the vehicle's MAVLink system id (vehicle index + 1)")
    p.add_argument("--out", type=Path, default=None, metavar="FILE",
                   help="also write the raw 32-byte key to FILE (0600), for --signing-key")
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    path = args.secret / MAVLINK_SECRET_FILE if args.secret.is_dir() else args.secret
    secret = load_key(path)
    if not 1 <= args.sysid <= 255:
        raise ConfigError("sysid", f"a MAVLink system id is 1..255, got {args.sysid}")
    if args.out is not None:
        write_raw_key(args.out, vehicle_key(secret, args.sysid))
    print(vehicle_passphrase(secret, args.sysid))
    return 0
