"""`enclose host DEPLOYMENT.toml --host NAME`: the part of a swarm that lives on this host.

Starts this host's Zenoh router and the processes the deployment file places here
(deploy.deployment, deploy.host_launch).  Run it on every host; the host of the
`launcher` waits until the whole swarm is linked, starts and stops the run and writes
the outputs (its recorder's, if the recorder is there).  `--all` runs every host of the
file from here (namespaced test hosts: what `enclose run --hosts K` does).
"""

from __future__ import annotations

import argparse
import signal
from pathlib import Path
from typing import Any

from deploy.commands.run import _interrupt
from deploy.deployment import load_deployment
from deploy.host_launch import HostLaunch
from deploy.restarts import add_supervision_arguments
from deploy.verdict import add_json_argument
from transport.errors import DeployError


def register(sub: Any) -> None:
    p = sub.add_parser("host", help="run this host's part of a swarm spread over hosts")
    p.add_argument("deployment", type=Path, help="deployment file (TOML, deploy/deployment.py)")
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--host", default=None, help="this host's name in the file")
    which.add_argument("--all", action="store_true", help="every host (namespaced test hosts)")
    p.add_argument("--duration", type=float, default=None, help="seconds after the start")
    p.add_argument("--out", type=Path, default=Path("runs/host"), help="run directory")
    p.add_argument("--credentials", dest="credentials_dir", default=None, metavar="DIR",
                   help="this host's copy of `enclose keys DIR --routers K` (default: fresh "
                   "per run, which works only with --all)")
    p.add_argument("--noise-std-m", type=float, default=0.0, help="noise on target observations")
    p.add_argument("--zenoh-config", default=None, metavar="JSON5", help="your Zenoh config")
    p.add_argument("--link-timeout", type=float, default=120.0,
                   help="seconds to wait for the whole swarm to link")
    p.add_argument("--insecure", action="store_true",
                   help="no mTLS/ACL, no MAVLink signing (not recommended)")
    add_json_argument(p)
    add_supervision_arguments(p)
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    dep = load_deployment(args.deployment)
    local = tuple(range(len(dep.hosts))) if args.all else (dep.index_of(args.host),)
    if not args.all and args.credentials_dir is None and not args.insecure:
        raise DeployError("--credentials DIR: hosts of one swarm must share its CA "
                          "(`enclose keys DIR SCENARIO --swarm NAME --routers K`)")
    args.scenario = dep.scenario
    launch = HostLaunch(dep, local, args, args.out.resolve(), 1.0)
    launch.duration_s = (launch.scenario.run.duration_s if args.duration is None
                         else args.duration)
    if launch.duration_s <= 0:
        raise DeployError("--duration must be > 0")
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        return launch.execute()
    finally:
        signal.signal(signal.SIGTERM, previous)
