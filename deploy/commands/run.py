"""`enclose run`: the whole swarm as OS processes on this machine, linked by Zenoh on loopback."""

from __future__ import annotations

import argparse
import signal
import time
from pathlib import Path
from types import FrameType
from typing import Any

from agents.network_args import add_network_arguments, apply_network_arguments
from agents.scenario.file import load_scenario
from deploy.launch import Launch
from deploy.live_args import add_live_arguments
from deploy.netns.hosts import add_hosts_arguments, run_on_hosts
from deploy.netns.run import add_netns_arguments, netns_requested, run_in_namespace
from deploy.restarts import add_supervision_arguments
from deploy.verdict import add_json_argument
from transport.errors import DeployError


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
    add_live_arguments(p)
    add_json_argument(p)
    add_supervision_arguments(p)
    add_network_arguments(p)
    add_netns_arguments(p)
    add_hosts_arguments(p)
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    scenario = apply_network_arguments(load_scenario(args.scenario), args)  # fail early
    duration = scenario.run.duration_s if args.duration is None else args.duration
    if duration <= 0:
        raise DeployError("--duration must be > 0")
    if scenario.network.link != "tcp" and not args.insecure:
        raise DeployError(
            f"network.link = {scenario.network.link!r} cannot be authenticated (Zenoh mTLS "
            "runs over TCP): use link tcp, or --insecure"
        )
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = (args.out or Path("runs") / f"run-{scenario.name}-{stamp}").resolve()
    swarm = args.swarm or f"{scenario.name}-{stamp}".replace("_", "-")
    previous = signal.signal(signal.SIGTERM, _interrupt)  # SIGTERM stops as cleanly as Ctrl-C
    try:
        if args.hosts is not None:  # K namespaced hosts: deploy.netns.hosts
            return run_on_hosts(args, out, swarm, duration)
        if netns_requested(args):  # the same run, launched again inside a lossy namespace
            return run_in_namespace(args, out, swarm, duration)
        return Launch(scenario, args, out, swarm, duration).execute()
    finally:
        signal.signal(signal.SIGTERM, previous)


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt
