"""Plumbing every swarm process shares: arguments, the bus, signals, the tick loop, status.

Entry points (follower, target, simulator, recorder) only wire these together.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import signal
import time
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from types import FrameType

from agents.network_args import add_network_arguments, apply_network_arguments
from agents.phases import mark
from agents.scenario.file import load_scenario
from agents.scenario.model import Scenario
from transport.bus import Bus
from transport.clock_sync import parse_clock_hosts
from transport.codec import encode
from transport.credentials import Identity
from transport.errors import EncloseError
from transport.keys import SwarmKeys
from transport.messages import ProcessStatus, Stamper
from transport.network_schema import NetworkConfig
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

log = logging.getLogger(__name__)
Clock = Callable[[], float]


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


def load_run_scenario(args: argparse.Namespace) -> Scenario:
    """The scenario named on the command line, with the command line's network overrides;
    checked over the whole run unless the entry point set `whole_run_checks=False`
    (agents.follower: see agents.scenario.checks.check_admissible)."""
    whole_run = getattr(args, "whole_run_checks", True)
    return apply_network_arguments(load_scenario(args.scenario, whole_run), args)


def open_bus(args: argparse.Namespace, arrival_stamps: bool = False) -> Bus:
    """The process's bus; with no --listen it listens on an OS-chosen port of the run's
    link protocol (`[network] link`, or --link), so that every link of the mesh uses it.
    `arrival_stamps`: stamp each sample's arrival (one-way latency, transport.link_stats)."""
    network = load_run_scenario(args).network
    cfg = ZenohConfig(
        listen=tuple(args.listen),
        connect=tuple(args.connect),
        user_config_path=args.zenoh_config,
        link=network.link,
        runtime=network.zenoh_runtime,
        identity=None if args.credentials is None else Identity.load(args.credentials),
        mode=getattr(args, "mode", "peer"),
        arrival_stamps=arrival_stamps,
    )
    bus = ZenohBus(cfg)
    mark("bus_open")  # the session is up: its first link (TLS handshake included) is made
    if getattr(args, "clock_host", None) is not None:
        bus.start_clock_sync(SwarmKeys(args.swarm), f"router-{args.clock_host}",
                             clock_of=parse_clock_hosts(args.clock_hosts))
    return bus


def apply_agent_sched(network: NetworkConfig) -> None:
    """Run this process SCHED_BATCH if the scenario says so (NetworkConfig.agent_sched).

    Called on the main thread before the bus opens: Linux sets a thread's policy, and the
    threads made later (Zenoh's, the stall guard) inherit it.  A batch thread does not
    preempt the running one when it wakes (the scheduler's tick does); it gets the same
    share of the CPU.  No privilege is needed."""
    if network.agent_sched == "batch":
        try:
            os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
        except (OSError, AttributeError) as exc:  # not Linux: the default policy stays
            log.warning("agent_sched batch not applied: %s", exc)


def process_main(
    parser: argparse.ArgumentParser,
    argv: Sequence[str] | None,
    run: Callable[[argparse.Namespace], int],
    name: Callable[[argparse.Namespace], str],
) -> int:
    """Parse, set up logging, run; a named error becomes a logged line and exit code 2."""
    mark("main")  # the entry point's imports are done
    args = parser.parse_args(argv)
    setup_logging(args.log_level, name(args))
    try:
        return profiled(run, args, name(args))
    except EncloseError as exc:
        logging.getLogger(f"enclose.{name(args)}").error("%s: %s", type(exc).__name__, exc)
        return 2


def profiled(run: Callable[[argparse.Namespace], int], args: argparse.Namespace,
              name: str) -> int:
    """`run`, under cProfile when ENCLOSE_PROFILE_DIR names a folder: the profile of each
    process lands in <folder>/<name>.prof (read it with `python -m pstats`).

    ENCLOSE_PROFILE_ONLY (names, comma-separated: `follower-3,sim`) profiles those alone:
    cProfile doubles a process's CPU, and 64 profiled followers starve 2 cores."""
    folder = os.environ.get("ENCLOSE_PROFILE_DIR")
    only = os.environ.get("ENCLOSE_PROFILE_ONLY", "")
    if not folder or (only and name not in {n.strip() for n in only.split(",")}):
        return run(args)
    import cProfile

    profiler = cProfile.Profile(time.thread_time)  # CPU, not wall: sleeps and preemption out
    try:
        return profiler.runcall(run, args)
    finally:
        os.makedirs(folder, exist_ok=True)
        profiler.dump_stats(os.path.join(folder, f"{name}.prof"))


def setup_logging(level: str, name: str) -> None:
    logging.basicConfig(
        level=level.upper(), format=f"%(asctime)s %(levelname)s {name} %(name)s: %(message)s"
    )


@dataclass
class StopFlag:
    """Set by SIGINT/SIGTERM; the loop checks it, so shutdown happens between ticks.

    While `interrupt` is true (blocking start-up phases that do not look at the flag)
    the signal raises KeyboardInterrupt instead, so that `with` blocks still close.
    """

    raised: bool = False
    signum: int | None = None
    interrupt: bool = False

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        self.raised, self.signum = True, signum
        if self.interrupt:
            raise KeyboardInterrupt


@contextmanager
def stop_on_signals() -> Iterator[StopFlag]:
    flag = StopFlag()
    previous = {s: signal.signal(s, flag) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield flag
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@dataclass
class Ticker:
    """Fixed-rate schedule on an injected clock: `wait()` sleeps to the next tick.

    Ticks fall on the grid k * period + phase of the clock, so processes sharing a
    clock can be staggered (each follower its own phase) instead of all ticking at
    once and always reading their neighbours' data from the tick before.
    """

    period_s: float
    clock: Clock = time.time
    sleep: Callable[[float], None] = time.sleep
    phase_s: float = 0.0
    overruns: int = 0
    ticks: int = 0
    _next_s: float | None = None

    def _grid_after(self, t_s: float) -> float:
        k = math.ceil((t_s - self.phase_s) / self.period_s)
        return k * self.period_s + self.phase_s

    def wait(self) -> float:
        """Sleep until the next tick and return its time; a late tick is counted, not caught up."""
        now = self.clock()
        if self._next_s is None:
            self._next_s = self._grid_after(now)
        elif now > self._next_s + self.period_s:
            self.overruns += 1
            self._next_s = self._grid_after(now)  # skip missed ticks rather than burst
        if now < self._next_s:
            self.sleep(self._next_s - now)
        self._next_s += self.period_s
        self.ticks += 1
        return self.clock()


@dataclass
class StatusReporter:
    """Publishes ProcessStatus at about 1 Hz, or at once on a state change."""

    bus: Bus
    keys: SwarmKeys
    role: str
    index: int
    period_s: float = 1.0
    counters: Counter[str] = field(default_factory=Counter)
    state: str = "starting"
    _stamper: Stamper | None = None
    _last_s: float = -1e18

    def set(self, state: str, detail: str = "", extra: Mapping[str, int] | None = None) -> None:
        changed = state != self.state
        self.state = state
        self.publish(detail, extra, force=changed)

    def due(self) -> bool:
        """True when the next periodic status is due: build costly counters only then."""
        return self.bus.now_s() - self._last_s >= self.period_s

    def publish(
        self, detail: str = "", extra: Mapping[str, int] | None = None, force: bool = False
    ) -> None:
        now = self.bus.now_s()
        if not force and now - self._last_s < self.period_s:
            return
        self._last_s = now
        if self._stamper is None:
            self._stamper = Stamper(f"{self.role}-{self.index}", self.bus.now_s)
        counters = {**self.counters, **(extra or {})}
        msg = ProcessStatus(
            self._stamper.header(),
            self.role,
            self.index,
            self.state,
            {k: int(v) for k, v in counters.items()},
            detail,
        )
        self.bus.publish(self.keys.status(self.role, self.index), encode(msg))
