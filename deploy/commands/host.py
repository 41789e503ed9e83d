"""`enclose host DEPLOYMENT.toml --host NAME`: the part of a swarm that lives on this host.

Starts this host's Zenoh router and the processes the deployment file places here
(deploy.hosts.deployment, deploy.hosts.host_launch).  Run it on every host; the host of the
`launcher` waits until the whole swarm is linked, starts and stops the run and writes
the outputs (its recorder's, if the recorder is there).  `--all` runs every host of the
file from here (namespaced test hosts: what `enclose run --hosts K` does).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.shell.network_args import NetworkOptions
from deploy.hosts.deployment import load_deployment
from deploy.hosts.host_launch import HostLaunch
from deploy.launch.launch_options import LaunchOptions, add_figures_argument, add_journal_argument
from deploy.procs.interrupts import interrupts
from deploy.procs.restarts import add_supervision_arguments
from deploy.report.verdict import add_json_argument
from errors import DeployError


def register(sub: Any) -> None:
    p = sub.add_parser("host", help="run this host's part of a swarm spread over hosts")
    p.add_argument("deployment", type=Path,
                   help="deployment file (TOML, deploy/hosts/deployment.py)")
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--host", default=None, help="this host's name in the file")
    which.add_argument("--all", action="store_true", help="every host (namespaced test hosts)")
    p.add_argument("--duration", type=float, default=None, help="seconds after the start")
    p.add_argument("--out", type=Path, default=Path("runs/host"), help="run directory")
    p.add_argument("--credentials", dest="credentials_dir", default=None, metavar="DIR",
                   help="this host's folder of `enclose keys OUT_DIR --deployment FILE` "
                   "(OUT_DIR/<host>; with --all, OUT_DIR itself; default: fresh per run, "
                   "which works only with --all)")
    p.add_argument("--noise-std-m", type=float, default=0.0, help="noise on target observations")
    p.add_argument("--zenoh-config", default=None, metavar="JSON5", help="your Zenoh config")
    p.add_argument("--link-timeout", type=float, default=120.0,
                   help="seconds to wait for the whole swarm to link")
    p.add_argument("--insecure", action="store_true",
                   help="no mTLS/ACL, no MAVLink signing (not recommended)")
    add_json_argument(p)
    add_journal_argument(p)
    add_figures_argument(p)
    add_supervision_arguments(p)
    p.set_defaults(func=_main)


@dataclass(frozen=True)
class HostOptions:
    """`enclose host`'s command line (the scenario is the deployment file's)."""

    launch: LaunchOptions
    deployment: Path
    host: str | None = None  # this host's name in the file; None: every host (--all)
    duration_s: float | None = None  # None: the scenario's
    out: Path = Path("runs/host")

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> HostOptions:
        # No live view (its recorder may be in a namespace), no network flags.
        launch = LaunchOptions.from_namespace(args, None, None, NetworkOptions(),
                                              credentials_dir=args.credentials_dir)
        return cls(launch, args.deployment, args.host, args.duration, args.out)


def _main(args: argparse.Namespace) -> int:
    return run(HostOptions.from_namespace(args))


def run(opts: HostOptions) -> int:
    dep = load_deployment(opts.deployment)
    every = tuple(range(len(dep.hosts)))
    local = every if opts.host is None else (dep.index_of(opts.host),)
    if opts.host is not None and opts.launch.credentials_dir is None \
            and not opts.launch.insecure:
        raise DeployError("--credentials DIR: hosts of one swarm must share its CA "
                          "(`enclose keys OUT_DIR --deployment FILE`, then OUT_DIR/<host>)")
    launch = HostLaunch(dep, local, opts.launch, opts.out.resolve(), 1.0,
                        every_host=opts.host is None)
    launch.duration_s = (launch.scenario.run.duration_s if opts.duration_s is None
                         else opts.duration_s)
    if launch.duration_s <= 0:
        raise DeployError("--duration must be > 0")
    with interrupts():
        return launch.execute()
