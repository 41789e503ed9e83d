"""One `enclose run` on this machine: start the swarm's processes, link, fly, stop, report.

`deploy.commands.run` parses the command line and hands over to `Launch.execute`; how the run
ends (the processes stopped in order, launch.json, the exit code) is `deploy.launch.launch_end`,
and its ports are chosen by `deploy.launch.ports.run_ports`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from agents.scenario.faults import FaultSpec, parse_fault_flag
from agents.scenario.model import Scenario
from agents.shell.law_args import law_overrides
from agents.shell.network_args import network_overrides
from agents.shell.phases import mark
from agents.weather.windows import window_strengths
from deploy.json_files import write_json_atomic
from deploy.launch.fault_injector import FaultRunner
from deploy.launch.launch_end import exit_code, launch_report, stop_in_order
from deploy.launch.launch_options import LaunchOptions
from deploy.launch.live_args import announce_live_url, pin_live_port, recorder_live_argv
from deploy.launch.ports import run_ports
from deploy.launch.run_board import BoardView, LiveBoard
from deploy.launch.run_monitor import launch_view
from deploy.launch.run_secrets import RunSecrets
from deploy.launch.status_board import StatusBoard
from deploy.procs.restarts import RestartPolicy, Watchdog
from deploy.procs.supervisor import Child, Supervisor
from deploy.report.cpu_load import CpuSampler, load_1min, machine_ticks, start_saturation_note
from errors import DeployError
from transport.access import sender_ids
from transport.bus import Bus, Congestion
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.messages import RunControl, Stamper
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

log = logging.getLogger("enclose.run")
START_DELAY_S = 1.0
PROGRESS_PERIOD_S = 2.0
START_REPEAT_S = 1.0  # the start word again, for processes (re)started after it
STARTUP_RESTARTS = 2  # per process before the start: a third death there is not bad luck


def gust_window_argv(faults: tuple[FaultSpec, ...]) -> list[str]:
    """The simulator's --gust-window flags: the strengths of the wind windows the fault
    injector will open (the scenario's and --fault's), in time order."""
    return [arg for s in window_strengths(faults) for arg in ("--gust-window", repr(s))]


class Launch:
    """One run: wiring of all processes, the start word, progress, and an orderly stop."""

    # The followers are forked by a fork server (deploy.procs.zygote), started first thing.
    forks_followers = True
    sends_control = True  # the start and stop words (deploy.hosts.host_launch: its host only)

    def __init__(
        self, scenario: Scenario, opts: LaunchOptions, out: Path, swarm: str, duration_s: float
    ) -> None:
        self.scenario, self.opts, self.out, self.duration_s = scenario, opts, out, duration_s
        self.keys = SwarmKeys(swarm)
        self.sup = Supervisor(out / "logs")
        self.vehicle_base, self.adapter_base, self.endpoint = run_ports(
            scenario.n + scenario.m, scenario.network.link, not opts.insecure, opts.port_range)
        self.secrets = RunSecrets(None)
        self.timings: dict[str, float] = {}
        self.board = StatusBoard(sender_ids(scenario.n, scenario.m))
        # The statuses as the flight ended, before the processes stop: a vehicle whose
        # follower has stopped fails safe, so the final counts include the shutdown.
        self.status_at_stop: dict[str, Any] | None = None
        self.policy = RestartPolicy(opts.restart, opts.max_restarts)
        self.watchdog: Watchdog | None = None
        flags = [parse_fault_flag(f, scenario.n, scenario.m) for f in opts.faults]
        self.faults = (*scenario.faults, *(f for f in flags if f is not None))
        self.injector: FaultRunner | None = None
        self.control_stamper: Stamper | None = None
        self.live_url: str | None = None
        self.started_s = time.monotonic()
        self.t0_s = float("inf")  # monotonic time of the experiment's start, once known
        self.cpu = CpuSampler()  # what each process cost, sampled while flying (see fly)
        self.spawn_ticks: tuple[int, int] | None = None  # the machine's, as the spawns begin

    def common(self) -> list[str]:
        extra = ["--zenoh-config", self.opts.zenoh_config] if self.opts.zenoh_config else []
        extra += network_overrides(self.opts.network) + law_overrides(self.opts.law)
        return ["--scenario", self.opts.scenario_ref(), "--swarm", self.keys.swarm, *extra]

    def journal_argv(self) -> list[str]:
        """A follower's input journal, in the run directory (enclose replay)."""
        on = self.scenario.run.journal if self.opts.journal is None else self.opts.journal
        return ["--journal", str(self.out / "journal")] if on else []

    def recorder_output_argv(self) -> list[str]:
        """What the recorder leaves out: noiseless target observations (the truth's target
        positions again, deploy.recording.loop), and the figures if asked."""
        return ([] if self.opts.noise_std_m > 0.0 else ["--no-sensor"]) + (
            [] if self.opts.figures else ["--no-figures"])

    def start_all(self) -> None:
        c, s = self.common(), self.scenario
        mav = ["--mav-local-base", str(self.adapter_base),
               "--mav-vehicle-base", str(self.vehicle_base)]
        self.sup.start(
            "sim", "sim_backend.swarm_sim",
            [*c, "--listen", self.endpoint, "--base-port", str(self.vehicle_base),
             "--send-base-port", str(self.adapter_base),
             "--noise-std-m", str(self.opts.noise_std_m), *self.secrets.args_for("sim"),
             *gust_window_argv(self.faults)],
            fork=True,
        )
        joins = [*c, "--connect", self.endpoint]
        sec = self.secrets.args_for
        # It imports what it alone needs (MCAP, its outputs) after the fork: not in the movers.
        self.sup.start(
            "recorder", "deploy.recording.recorder",
            [*joins, "--out", str(self.out), *sec("recorder"), *recorder_live_argv(self.opts.live),
             *self.recorder_output_argv()],
            fork=True,
        )
        # Targets first: the followers come from the fork server, which may still be
        # importing (deploy.procs.zygote).
        for j in range(s.m):
            argv = [*joins, *mav, "--index", str(j), *sec(f"target-{j}")]
            self.sup.start(f"target-{j}", "agents.target", argv, fork=True)
        for i in range(s.n):
            argv = [*joins, *mav, "--index", str(i), *sec(f"follower-{i}"),
                    *self.journal_argv()]
            self.sup.start(f"follower-{i}", "agents.follower.main", argv, fork=True)

    def expected_tokens(self) -> set[str]:
        k, s = self.keys, self.scenario
        return (
            {k.alive("sim", 0), k.alive("recorder", 0)}
            | {k.alive("follower", i) for i in range(s.n)}
            | {k.alive("target", j) for j in range(s.m)}
        )

    def wait_linked(self, bus: Bus, t0: float) -> None:
        """Until every process declared itself linked; a start-up that fails on a
        saturated machine says so (deploy.report.cpu_load.start_saturation_note)."""
        try:
            self._until_linked(bus, t0)
        except DeployError as exc:
            note = start_saturation_note(self.spawn_ticks, machine_ticks(), load_1min(),
                                         len(self.sup.children))
            if note is None:
                raise
            raise DeployError(f"{exc}\n{note}") from exc

    def _until_linked(self, bus: Bus, t0: float) -> None:
        watch = bus.watch_alive(self.keys.all_alive())
        expected, shown = self.expected_tokens(), -1
        deadline = t0 + self.opts.link_timeout_s
        while True:
            alive = watch.poll() & expected
            if alive == expected:
                return
            self._check_children()
            if len(alive) != shown:
                shown = len(alive)
                log.info("linked %d/%d processes", shown, len(expected))
            if time.monotonic() > deadline:
                missing = sorted(
                    k.rsplit("/", 2)[-2] + "-" + k.rsplit("/", 1)[-1] for k in expected - alive
                )
                raise DeployError(
                    f"not linked after {self.opts.link_timeout_s:.0f} s: {', '.join(missing)}"
                )
            time.sleep(0.05)

    def _check_children(self) -> None:
        """Before the start, a process that dies (a vehicle that did not answer its
        take-off while 60 processes were starting on 2 cores) is restarted as the policy
        says, at most STARTUP_RESTARTS times; one that stays dead ends the launch."""
        if self.watchdog is None:
            startup = replace(self.policy,
                              max_restarts=min(self.policy.max_restarts, STARTUP_RESTARTS))
            self.watchdog = Watchdog(self.sup, startup, time.monotonic(), self._before_restart)
        try:
            self.watchdog.check()
        finally:
            self._raise_if_dead_for_good(self.watchdog)

    def _raise_if_dead_for_good(self, dog: Watchdog) -> None:
        dead = dog.dead_for_good()
        if dead:
            c = dead[0]
            raise DeployError(
                f"{c.name} exited with code {c.exit_code}; last lines of {c.log_path}:\n{c.tail()}"
            )

    def execute(self) -> int:
        self.out.mkdir(parents=True, exist_ok=True)
        log.info("run directory %s; swarm %s; Zenoh rendezvous %s; vehicles on UDP "
                 "127.0.0.1:%d+; agents on UDP 127.0.0.1:%d+", self.out, self.keys.swarm,
                 self.endpoint, self.vehicle_base, self.adapter_base)
        t0 = time.monotonic()
        if self.forks_followers:
            self.sup.start_fork_server()
        interrupted = False
        try:
            self.secrets = self.make_secrets()
        except BaseException:
            self.sup.end_forks()
            raise
        mark("credentials")
        self.spawn_ticks = machine_ticks()
        try:
            self.start_all()
            self.sup.end_forks()
            mark("spawned")
            with self.open_bus() as bus:
                mark("bus_open")
                interrupted = self.link_and_fly(bus, t0)
        except KeyboardInterrupt:
            interrupted = True
            log.warning("interrupted before the start")
        finally:
            if self.injector is not None:
                self.injector.resume_all()
            self.sup.stop_all()
            self.write_launch()
        return exit_code(self, interrupted)

    def link_and_fly(self, bus: Bus, t0: float) -> bool:
        """Wait for every process, fly the run, stop it in order; True if interrupted
        (Ctrl-C) during the flight, whose recording is kept."""
        self.board.subscription = bus.subscribe(self.keys.all_status())
        self.wait_linked(bus, t0)
        mark("linked")
        self.timings["link_s"] = time.monotonic() - t0
        self.timings["linked_wall_s"] = time.time()
        log.info("all %d processes linked in %.1f s", len(self.expected_tokens()),
                 self.timings["link_s"])
        self.live_url = announce_live_url(self.opts.live, self.out)
        interrupted = False
        try:
            self.fly(bus)
        except KeyboardInterrupt:
            interrupted = True
            log.warning("interrupted: stopping the run, keeping what was recorded")
        self.status_at_stop = self.board.as_dict()
        self.write_launch()  # the recorder draws its events on the figures
        if self.sends_control:
            stop_word = RunControl(self._stamper(bus).header(), "stop", bus.now_s(), 0.0)
            bus.publish(self.keys.control(), encode(stop_word))
        stop_in_order(self)
        return interrupted

    def make_secrets(self) -> RunSecrets:
        s = self.scenario
        return RunSecrets.make_apart(self.out, self.keys, s.n, s.m, self.opts.insecure,
                                     meanwhile=self.sup.preload)

    def open_bus(self) -> ZenohBus:
        """The launcher's own session (deploy.hosts.host_launch: a client of its host's router)."""
        return ZenohBus(ZenohConfig(
            connect=(self.endpoint,), user_config_path=self.opts.zenoh_config,
            link=self.scenario.network.link, identity=self.secrets.identity("launcher"),
            runtime=self.scenario.network.zenoh_runtime,
            lease_s=self.scenario.network.zenoh_lease_s))

    def fly(self, bus: Bus) -> None:
        start = bus.now_s() + START_DELAY_S
        stamper = self._stamper(bus)

        def word() -> bytes:  # repeats keep the start stamp and carry their own seq
            return encode(RunControl(stamper.header(), "start", start, self.duration_s))

        t0 = self.t0_s = time.monotonic() + START_DELAY_S
        # Over the whole flight and its steady half: deploy.launch.launch_end.load_report.
        self.cpu = CpuSampler(windows_from_s=(t0, t0 + 0.5 * self.duration_s))
        if self.watchdog is None:
            self.watchdog = Watchdog(self.sup, self.policy, t0, self._before_restart)
        else:  # the one that watched the start-up: its events and restarts carry over
            self.watchdog.rebase(t0, self.policy, self._before_restart)
        self.injector = FaultRunner(
            self.sup, self.faults, t0, self.watchdog.events, self.watchdog.pending,
            self._before_restart,
        )
        next_word = start
        bus.publish(self.keys.control(), word())  # BLOCK: the first must not be lost
        # The repeats are replaced a second later: a consumer that stops reading must not
        # hold the launcher's loop (its faults, its watchdog) for Zenoh's close timeout.
        repeat = bus.declare_publisher(self.keys.control(), Congestion.DROP)
        with LiveBoard(self.view, PROGRESS_PERIOD_S) as board:
            while bus.now_s() < start + self.duration_s:
                self.injector.check()
                self.cut_check(time.monotonic() - t0)
                self.watchdog.check()
                self.board.collect()
                if bus.now_s() >= next_word:  # same start stamp: a repeat changes nothing
                    next_word += START_REPEAT_S
                    repeat.put(word())
                    self._sample_cpu()
                board.tick()
                time.sleep(0.05)

    def cut_check(self, t_s: float) -> None:
        """Network faults cut by the OS at experiment time `t_s` (deploy.hosts.host_launch)."""

    def _sample_cpu(self) -> None:
        self.cpu.sample(time.monotonic(), {c.name: c.pid for c in self.sup.children})

    def view(self) -> BoardView:
        """What the live board shows now (deploy.launch.run_board)."""
        return launch_view(self)

    def _stamper(self, bus: Bus) -> Stamper:
        """The launcher's one sequence of control words (repeats are not stale)."""
        if self.control_stamper is None:
            self.control_stamper = Stamper("launcher-0", bus.now_s)
        return self.control_stamper

    def _before_restart(self, child: Child) -> None:
        """A restarted recorder starts a new MCAP: keep the dead one's beside it.  A
        restarted follower joins a running swarm (agents.follower.main --join)."""
        mcap = self.out / "recording.mcap"
        if child.name == "recorder" and mcap.exists():
            mcap.rename(self.out / f"recording-part{child.restarts + 1}.mcap")
        if child.name == "recorder":
            pin_live_port(child.argv, self.live_url)
        running = time.monotonic() >= self.t0_s  # before the start, all begin together
        if running and child.name.startswith("follower-") and "--join" not in child.argv:
            child.argv.append("--join")

    def write_launch(self) -> None:
        write_json_atomic(self.out / "launch.json", self.report())

    def report(self) -> dict[str, Any]:
        return launch_report(self)
