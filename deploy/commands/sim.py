"""`enclose sim [SCENARIO | --vehicles N]`: the vehicle simulator alone, for any MAVLink GCS/SDK.

Also runnable as `python -m deploy.commands.sim ...` (same options) without the other subcommands.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from types import FrameType
from typing import Any

from agents.loading.scenario_file import load_scenario
from agents.mavlink.modes import FLAVOURS
from agents.mavlink.signing_keys import load_key
from agents.scenario.model import HomeConfig, VehicleConfig
from errors import EncloseError
from sim_backend.runtime import SimConfig, Simulator, grid_spawn_ned, spawn_points_ned
from sim_backend.sim_values import parse_peer_hosts

log = logging.getLogger("enclose.sim")


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("sim", help="run the MAVLink vehicle simulator alone",
                                   description=__doc__)
    add_arguments(parser)
    parser.set_defaults(func=_main)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    which = parser.add_mutually_exclusive_group()
    which.add_argument("scenario", nargs="?", default=None,
                       help="shipped scenario name or TOML path (default: the paper's case)")
    which.add_argument("--vehicles", type=int, default=None, metavar="N",
                       help="N vehicles on a 5 m grid instead of a scenario")
    parser.add_argument("--flavour", choices=FLAVOURS, default=None,
                        help="autopilot flavour (default: the scenario's, else px4)")
    parser.add_argument("--rate-hz", type=float, default=50.0, help="simulation tick rate")
    parser.add_argument("--telemetry-hz", type=float, default=50.0,
                        help="default rate of LOCAL_POSITION_NED, GLOBAL_POSITION_INT, ATTITUDE")
    parser.add_argument("--host", default="127.0.0.1", help="loopback address to use")
    parser.add_argument("--base-port", type=int, default=14580,
                        help="vehicle i listens on BASE+i (PX4 SITL: 14580)")
    parser.add_argument("--send-base-port", type=int, default=14540,
                        help="vehicle i sends telemetry to SEND_BASE+i (PX4 SITL: 14540)")
    keys = parser.add_mutually_exclusive_group()
    keys.add_argument("--signing-key", default=None, metavar="FILE",
                      help="32-byte MAVLink 2 signing key of every vehicle: they drop unsigned "
                      "or badly signed messages (default: unsigned, so any ground station "
                      "connects)")
    keys.add_argument("--signing-secret", default=None, metavar="FILE",
                      help="32-byte run secret: each vehicle enforces signing with its own "
                      "key derived from it (`enclose vehicle-key FILE SYSID` prints one)")
    parser.add_argument("--mav-peers", default=None, metavar="ADDR,ADDR,...",
                        help="the one client address of each vehicle, in order: vehicle i "
                        "then hears (ADDR_i, send base + i) alone (default: anyone, as PX4 "
                        "SITL: a ground station you start later)")
    parser.add_argument("--duration-s", type=float, default=None,
                        help="stop after this much simulated time (default: until Ctrl-C)")


@dataclass(frozen=True)
class SimOptions:
    """`enclose sim`'s command line."""

    scenario: str | None = None  # None: the paper's case (unless `vehicles`)
    vehicles: int | None = None  # N vehicles on a grid instead of a scenario
    flavour: str | None = None  # None: the scenario's
    rate_hz: float = 50.0
    telemetry_hz: float = 50.0
    host: str = "127.0.0.1"
    base_port: int = 14580
    send_base_port: int = 14540
    signing_key: str | None = None  # key file: one key for every vehicle
    duration_s: float | None = None  # simulated time; None: until Ctrl-C
    signing_secret: str | None = None  # run secret file: a key per vehicle
    mav_peers: tuple[str, ...] = ()  # each vehicle's one client address; (): anyone

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> SimOptions:
        return cls(args.scenario, args.vehicles, args.flavour, args.rate_hz, args.telemetry_hz,
                   args.host, args.base_port, args.send_base_port, args.signing_key,
                   args.duration_s, args.signing_secret, parse_peer_hosts(args.mav_peers))


def build_simulator(opts: SimOptions) -> Simulator:
    if opts.vehicles is not None:
        if opts.vehicles < 1:
            raise EncloseError("--vehicles must be >= 1")
        spawn, vehicle, home = grid_spawn_ned(opts.vehicles), VehicleConfig(), HomeConfig()
    else:
        scenario = load_scenario(opts.scenario)
        spawn, vehicle, home = spawn_points_ned(scenario), scenario.vehicle, scenario.home
    cfg = SimConfig(rate_hz=opts.rate_hz, telemetry_hz=opts.telemetry_hz,
                    flavour=opts.flavour or vehicle.flavour, host=opts.host,
                    listen_base_port=opts.base_port, send_base_port=opts.send_base_port,
                    signing_key=None if opts.signing_key is None else load_key(opts.signing_key),
                    signing_secret=None if opts.signing_secret is None
                    else load_key(opts.signing_secret), peer_hosts=opts.mav_peers)
    return Simulator(spawn, vehicle, home, cfg)


def _main(args: argparse.Namespace) -> int:
    return run(SimOptions.from_namespace(args))


def run(opts: SimOptions) -> int:
    sim = build_simulator(opts)
    stop = {"flag": False}

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop["flag"] = True

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    ports = sim.listen_ports()
    log.info("%d %s vehicles, sysid 1..%d, listening on %s:%d..%d, sending to %s:%d..%d",
             sim.n, sim.cfg.flavour, sim.n, sim.cfg.host, ports[0], ports[-1], sim.cfg.host,
             sim.cfg.send_base_port, sim.cfg.send_base_port + sim.n - 1)
    max_ticks = None if opts.duration_s is None else round(opts.duration_s * sim.cfg.rate_hz)
    started = time.monotonic()
    try:
        stats = sim.run(lambda: stop["flag"], max_ticks)
    finally:
        sim.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    wall_s = time.monotonic() - started
    counters = " ".join(f"{k}={v}" for k, v in sorted(sim.counters.items()))
    print(f"sim stopped: ticks={stats.ticks} sim_time_s={sim.sim_time_s:.2f} wall_s={wall_s:.2f} "
          f"overruns={stats.overruns} resyncs={stats.resyncs} {counters}", flush=True)
    # Every received message by type and outcome: proves none was left unanswered.
    messages = " ".join(f"{k}={v}" for k, v in sorted(sim.messages.items()))
    print(f"sim messages: {messages}", flush=True)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="enclose sim", description=__doc__)
    add_arguments(parser)
    opts = SimOptions.from_namespace(parser.parse_args(argv))
    logging.basicConfig(level=logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        return run(opts)
    except EncloseError as exc:
        log.error("%s: %s", type(exc).__name__, exc)
        return 2


if __name__ == "__main__":
    sys.exit(main())
