"""`enclose run`: the whole swarm as OS processes on this machine, linked by Zenoh on loopback."""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.loading.scenario_file import load_scenario
from agents.scenario.net_faults import check_window
from agents.shell.law_args import add_law_arguments, apply_law_arguments
from agents.shell.network_args import NetworkOptions, add_network_arguments, apply_network_arguments
from deploy.hosts.namespaced_hosts import HostsOptions, add_hosts_arguments, run_on_hosts
from deploy.launch.launch_options import LaunchOptions, add_figures_argument, add_journal_argument
from deploy.launch.launcher import Launch
from deploy.launch.live_args import LiveOptions, add_live_arguments
from deploy.netns.netns_run import NetnsOptions, add_netns_arguments, run_in_namespace
from deploy.procs.interrupts import interrupts
from deploy.procs.restarts import add_supervision_arguments
from deploy.report.verdict import add_json_argument
from errors import DeployError


def register(sub: Any) -> None:
    p = sub.add_parser(
        "run", help="run the swarm: simulator, targets, one process per follower, recorder"
    )
    p.add_argument(
        "scenario", nargs="?", default=None, help="scenario TOML or shipped name (default: paper)"
    )
    p.add_argument(
        "--duration", type=float, default=None, help="seconds after the start (default: scenario)"
    )
    p.add_argument(
        "--out", type=Path, default=None, help="run directory (default: runs/run-<name>-<time>)"
    )
    p.add_argument("--swarm", default=None, help="swarm name on the bus (default: unique per run)")
    p.add_argument(
        "--port-range",
        default=None,
        metavar="LO-HI",
        help="take the MAVLink and Zenoh ports from LO-HI (default: the first free ones)",
    )
    p.add_argument("--noise-std-m", type=float, default=0.0, help="noise on target observations")
    p.add_argument("--zenoh-config", default=None, metavar="JSON5", help="your Zenoh config file")
    p.add_argument(
        "--link-timeout", type=float, default=120.0, help="seconds to wait for all to link"
    )
    p.add_argument(
        "--insecure",
        action="store_true",
        help="no Zenoh authentication/access control and no MAVLink signing (not recommended)",
    )
    add_journal_argument(p)
    add_figures_argument(p)
    add_live_arguments(p)
    add_json_argument(p)
    add_supervision_arguments(p)
    add_network_arguments(p)
    add_law_arguments(p)
    add_netns_arguments(p)
    add_hosts_arguments(p)
    p.set_defaults(func=_main)


@dataclass(frozen=True)
class RunOptions:
    """`enclose run`'s command line."""

    launch: LaunchOptions
    duration_s: float | None = None  # None: the scenario's
    out: Path | None = None  # None: runs/run-<name>-<time>
    swarm: str | None = None  # None: unique per run
    netns: NetnsOptions | None = None  # --netns: the run in a lossy namespace
    hosts: HostsOptions | None = None  # --hosts K: over namespaced hosts

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> RunOptions:
        launch = LaunchOptions.from_namespace(
            args, args.scenario, LiveOptions.from_namespace(args),
            NetworkOptions.from_namespace(args), port_range=args.port_range)
        return cls(launch, args.duration, args.out, args.swarm,
                   NetnsOptions.from_namespace(args), HostsOptions.from_namespace(args))


def _main(args: argparse.Namespace) -> int:
    return run(RunOptions.from_namespace(args))


def run(opts: RunOptions) -> int:
    launch = opts.launch
    scenario = apply_network_arguments(load_scenario(launch.scenario), launch.network)
    scenario = apply_law_arguments(scenario, launch.law)  # a bad law fails here, first
    duration = scenario.run.duration_s if opts.duration_s is None else opts.duration_s
    if duration <= 0:
        raise DeployError("--duration must be > 0")
    for fault in scenario.network.faults:
        check_window(fault, "--duration", duration)
    if scenario.network.link != "tcp" and not launch.insecure:
        raise DeployError(
            f"network.link = {scenario.network.link!r} cannot be authenticated (Zenoh mTLS "
            "runs over TCP): use link tcp, or --insecure"
        )
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = (opts.out or Path("runs") / f"run-{scenario.name}-{stamp}").resolve()
    swarm = opts.swarm or f"{scenario.name}-{stamp}".replace("_", "-")
    with interrupts():  # SIGTERM stops as cleanly as Ctrl-C
        if opts.hosts is not None:  # K namespaced hosts: deploy.hosts.namespaced_hosts
            return run_on_hosts(opts.hosts, scenario, launch, out, swarm, duration)
        if opts.netns is not None:  # the same run, launched again inside a lossy namespace
            return run_in_namespace(opts.netns, launch, out, swarm, duration)
        return Launch(scenario, launch, out, swarm, duration).execute()
