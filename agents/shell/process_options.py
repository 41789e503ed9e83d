"""A swarm process's command line and the typed options it is read into, once, in `main`.

`add_bus_arguments` / `BusOptions`: the scenario, the swarm and its Zenoh session (every
process on the bus); `add_vehicle_arguments` / `VehicleOptions`: the MAVLink link to the
process's vehicle (followers and targets); `AgentOptions`: a follower's or a target's
whole command line.  Past `main`, a process sees these objects, never an
`argparse.Namespace`.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

from agents.shell.law_args import LawOptions, add_law_arguments
from agents.shell.network_args import NetworkOptions, add_network_arguments


def add_bus_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", default=None, help="scenario TOML or shipped name")
    parser.add_argument("--swarm", default="enclose", help="swarm name (key prefix)")
    parser.add_argument(
        "--listen",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="Zenoh listen endpoint, e.g. tcp/127.0.0.1:7447 (repeatable)",
    )
    parser.add_argument(
        "--connect",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="Zenoh endpoint to connect to (repeatable)",
    )
    parser.add_argument(
        "--zenoh-config",
        default=None,
        metavar="JSON5",
        help="your own Zenoh config file, used as the base",
    )
    parser.add_argument(
        "--credentials",
        default=None,
        metavar="IDENTITY_JSON",
        help="this process's identity file (transport.credentials): mTLS + access control; "
        "without it the session is unauthenticated",
    )
    parser.add_argument("--mode", choices=("peer", "client"), default="peer",
                        help="Zenoh mode: peer (one host) or client of this host's router")
    parser.add_argument("--clock-host", type=int, default=None, metavar="K",
                        help="this process runs on host K of a swarm over hosts whose "
                        "clocks differ: map other hosts' stamps by their offsets, learnt "
                        "from the routers' clock probes (transport.clock_sync)")
    parser.add_argument("--clock-hosts", default="", metavar="S,S;S,..",
                        help="with --clock-host: every host's sender ids (e.g. "
                        "follower-0), hosts separated by ';' in router order")
    parser.add_argument("--log-level", default="INFO")
    add_network_arguments(parser)
    add_law_arguments(parser)


@dataclass(frozen=True)
class BusOptions:
    """The scenario, the swarm and the Zenoh session a process was told to use."""

    scenario: str | None = None  # shipped name or TOML path; None: the paper's case
    swarm: str = "enclose"
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    zenoh_config: str | None = None
    credentials: str | None = None  # identity file: mTLS + access control
    mode: str = "peer"
    clock_host: int | None = None
    clock_hosts: str = ""
    log_level: str = "INFO"
    network: NetworkOptions = field(default_factory=NetworkOptions)
    law: LawOptions = field(default_factory=LawOptions)

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> BusOptions:
        return cls(
            scenario=args.scenario, swarm=args.swarm, listen=tuple(args.listen),
            connect=tuple(args.connect), zenoh_config=args.zenoh_config,
            credentials=args.credentials, mode=args.mode, clock_host=args.clock_host,
            clock_hosts=args.clock_hosts, log_level=args.log_level,
            network=NetworkOptions.from_namespace(args), law=LawOptions.from_namespace(args),
        )


def add_vehicle_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mav-local-base", type=int, default=14540,
                        help="the adapter of vehicle v binds BASE+v (PX4 SITL: 14540)")
    parser.add_argument("--mav-vehicle-base", type=int, default=14580,
                        help="vehicle v listens on BASE+v (PX4 SITL: 14580)")
    parser.add_argument("--signing-key", default=None, metavar="FILE",
                        help="this vehicle's 32-byte MAVLink 2 signing key: sign everything "
                        "sent to it, refuse what it did not sign")
    parser.add_argument("--mav-vehicle-host", default=None, metavar="ADDR",
                        help="the vehicle's address when it is on another host (default: "
                        "127.0.0.1); the adapter then listens on every address")


@dataclass(frozen=True)
class VehicleOptions:
    """Where a process's vehicle is and how the link to it is signed."""

    mav_local_base: int = 14540
    mav_vehicle_base: int = 14580
    signing_key: str | None = None  # key file
    mav_vehicle_host: str | None = None  # None: this host

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> VehicleOptions:
        return cls(args.mav_local_base, args.mav_vehicle_base, args.signing_key,
                   args.mav_vehicle_host)


@dataclass(frozen=True)
class AgentOptions:
    """A follower's or a target's command line."""

    bus: BusOptions
    vehicle: VehicleOptions
    index: int
    join: bool = False  # a follower restarted into a running swarm
    journal: str | None = None  # a follower's input journal's folder (enclose replay)

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> AgentOptions:
        return cls(BusOptions.from_namespace(args), VehicleOptions.from_namespace(args),
                   args.index, bool(getattr(args, "join", False)),
                   getattr(args, "journal", None))
