"""Plumbing every swarm process shares: its scenario, the bus, signals, the tick loop,
status.  The command line itself is agents.shell.process_options.

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
from pathlib import Path
from types import FrameType
from typing import TypeVar

from agents.loading.scenario_file import load_scenario
from agents.scenario.model import Scenario
from agents.shell.law_args import apply_law_arguments
from agents.shell.lifeline import die_with_launcher
from agents.shell.network_args import apply_network_arguments
from agents.shell.phases import mark
from agents.shell.process_options import BusOptions
from errors import EncloseError
from transport.bus import Bus, Congestion, Publisher
from transport.clock_sync import clock_hosts_count, parse_clock_hosts
from transport.codec import encode
from transport.credentials import Identity
from transport.key_exprs import SwarmKeys
from transport.messages import ProcessStatus, Stamper
from transport.network_schema import NetworkConfig
from transport.peer_clock import PROCESS_BOOK, ClockBook
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

log = logging.getLogger(__name__)
Clock = Callable[[], float]
Options = TypeVar("Options")


def load_run_scenario(opts: BusOptions, whole_run: bool = True) -> Scenario:
    """The scenario named on the command line, with the command line's network and law
    overrides; checked over the whole run unless `whole_run` is false (agents.follower.main:
    see agents.scenario.checks.check_admissible).  A process calls it once and passes the
    result on."""
    scenario = apply_network_arguments(load_scenario(opts.scenario, whole_run), opts.network)
    return apply_law_arguments(scenario, opts.law)


def open_bus(opts: BusOptions, network: NetworkConfig, arrival_stamps: bool = False) -> Bus:
    """The process's bus; with no --listen it listens on an OS-chosen port of the run's
    link protocol (`network.link`: `[network] link`, or --link), so that every link of the
    mesh uses it.  `arrival_stamps`: stamp each sample's arrival (one-way latency,
    transport.link_stats)."""
    cfg = ZenohConfig(
        listen=opts.listen,
        connect=opts.connect,
        user_config_path=opts.zenoh_config,
        link=network.link,
        runtime=network.zenoh_runtime,
        lease_s=network.zenoh_lease_s,
        identity=None if opts.credentials is None else Identity.load(opts.credentials),
        mode=opts.mode,
        arrival_stamps=arrival_stamps,
    )
    bus = ZenohBus(cfg)
    mark("bus_open")  # the session is up: its first link (TLS handshake included) is made
    if opts.clock_host is not None:
        bus.start_clock_sync(SwarmKeys(opts.swarm), f"router-{opts.clock_host}",
                             clock_hosts_count(opts.clock_hosts),
                             clock_of=parse_clock_hosts(opts.clock_hosts))
    return bus


AUTOGROUP = Path("/proc/self/autogroup")


def apply_agent_sched(network: NetworkConfig, vehicle_agent: bool = True) -> None:
    """Run this process SCHED_BATCH if the scenario says so (NetworkConfig.agent_sched),
    and a vehicle's agent (a follower, a target) at the scenario's `agent_nice`
    (`yield_cpu`).  The recorder keeps its weight: it must keep up with every agent, and a
    recorder behind holds its backlog in memory.

    Called on the main thread before the bus opens: Linux sets a thread's policy and nice
    value, and the threads made later (Zenoh's, the stall guard) inherit them.  A batch
    thread does not preempt the running one when it wakes (the scheduler's tick does); it
    gets the same share of the CPU.  No privilege is needed for either."""
    if network.agent_sched == "batch":
        try:
            os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
        except (OSError, AttributeError) as exc:  # not Linux: the default policy stays
            log.warning("agent_sched batch not applied: %s", exc)
    if vehicle_agent and network.agent_nice > 0:
        log.info("agent_nice %d: %s", network.agent_nice, yield_cpu(network.agent_nice))


def yield_cpu(nice: int, autogroup: Path = AUTOGROUP, own_session: bool | None = None) -> str:
    """Take `nice` lower a scheduling weight; how: "autogroup", "thread" or "not applied".

    With autogroups (Linux's default), the CPU is shared between sessions, and every
    enclose process is a session of its own: only the session's weight, its autogroup's
    nice, moves its share; a thread's nice then orders threads within it alone.  Without
    autogroups the thread's nice is the weight.  Both are set; the autogroup only when this
    process leads its session (the autogroup is then this process's alone, never the
    user's shell's).  Raising a nice needs no privilege."""
    try:
        os.nice(nice)
    except OSError as exc:
        return f"not applied: {exc}"
    if own_session is None:
        own_session = os.getsid(0) == os.getpid()
    if not own_session:
        return "thread"
    try:
        autogroup.write_text(f"{nice}\n")
    except OSError:  # no autogroups in this kernel: the thread's nice is the weight
        return "thread"
    return "autogroup"


def process_main(
    parser: argparse.ArgumentParser,
    argv: Sequence[str] | None,
    read: Callable[[argparse.Namespace], Options],
    run: Callable[[Options], int],
    name: Callable[[Options], str],
) -> int:
    """Parse into typed options (`read`), set up logging, run; a named error becomes a
    logged line and exit code 2.  `log_level` is read from the parsed flags.  First of
    all, die with the launcher that started us, if one did (agents.shell.lifeline)."""
    die_with_launcher()
    mark("main")  # the entry point's imports are done
    args = parser.parse_args(argv)
    opts = read(args)
    setup_logging(args.log_level, name(opts))
    try:
        return profiled(run, opts, name(opts))
    except EncloseError as exc:
        logging.getLogger(f"enclose.{name(opts)}").error("%s: %s", type(exc).__name__, exc)
        return 2


def profiled(run: Callable[[Options], int], opts: Options, name: str) -> int:
    """`run(opts)`, under cProfile when ENCLOSE_PROFILE_DIR names a folder: the profile of
    each process lands in <folder>/<name>.prof (read it with `python -m pstats`).

    ENCLOSE_PROFILE_ONLY (names, comma-separated: `follower-3,sim`) profiles those alone:
    cProfile doubles a process's CPU, and 64 profiled followers starve 2 cores."""
    folder = os.environ.get("ENCLOSE_PROFILE_DIR")
    only = os.environ.get("ENCLOSE_PROFILE_ONLY", "")
    if not folder or (only and name not in {n.strip() for n in only.split(",")}):
        return run(opts)
    import cProfile

    profiler = cProfile.Profile(time.thread_time)  # CPU, not wall: sleeps and preemption out
    try:
        return profiler.runcall(run, opts)
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
    """Publishes ProcessStatus at about 1 Hz (DROP: the next replaces a lost one), or at
    once on a state change (BLOCK: sent once, outside the flight)."""

    bus: Bus
    keys: SwarmKeys
    role: str
    index: int
    period_s: float = 1.0
    counters: Counter[str] = field(default_factory=Counter)
    state: str = "starting"
    clocks: ClockBook = PROCESS_BOOK
    _stamper: Stamper | None = None
    _last_s: float = -1e18
    _periodic: Publisher | None = None  # the 1-Hz statuses: replaced by the next, DROP

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
        # Dropped clock probes (transport.peer_clock): non-zero only across hosts.
        counters = {**self.counters, **(extra or {}), **self.clocks.counters()}
        msg = ProcessStatus(
            self._stamper.header(),
            self.role,
            self.index,
            self.state,
            {k: int(v) for k, v in counters.items()},
            detail,
        )
        key = self.keys.status(self.role, self.index)
        if force:  # a state change, sent once: it must not be lost (Congestion)
            self.bus.publish(key, encode(msg))
            return
        if self._periodic is None:
            self._periodic = self.bus.declare_publisher(key, Congestion.DROP)
        self._periodic.put(encode(msg))
