"""The simulator of a swarm run: MAVLink vehicles, plus ground truth and target sensing on the bus.

    python -m sim_backend.swarm_sim --scenario paper --swarm S --listen tcp/127.0.0.1:P

Vehicles 0..n-1 are the followers, n..n+m-1 the targets.  Acting as each
follower's sensor, it publishes the targets that follower observes in the
scenario, stamped with the time they were true (optionally with noise); a follower on
another host is given them over a link to that host (`--sensor-link`, sim_backend.sensor_links).
"""

from __future__ import annotations

import argparse
import logging
import math
import signal
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from agents.frames import ned_to_enu
from agents.mavlink.signing_keys import agent_of_vehicle, load_key
from agents.membership.liveness import MembershipWatch
from agents.membership.member_hold import MemberHold
from agents.membership.ring import membership
from agents.scenario.model import Scenario
from agents.shell.phases import log_phases, mark
from agents.shell.process import (
    StatusReporter,
    load_run_scenario,
    open_bus,
    process_main,
    stop_on_signals,
)
from agents.shell.process_options import BusOptions, add_bus_arguments
from agents.weather.target_sensor import TargetSensor
from agents.weather.windows import WindSchedule, wind_begin_signal, wind_end_signal
from sim_backend.kinematics import FleetState
from sim_backend.runtime import SimConfig, Simulator, spawn_points_ned
from sim_backend.sensor_links import LinkBus, parse_sensor_link, sensor_buses
from sim_backend.sim_values import parse_peer_hosts
from sim_backend.vehicle_weather import weather_of
from transport.bus import Bus, Congestion
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.messages import Stamper, TargetObservation, TruthSnapshot, vec2, vec3

log = logging.getLogger("enclose.sim")


class SensorPublisher:
    """A tick hook: truth for the recorder and observations for each follower, at their rates."""

    def __init__(
        self,
        scenario: Scenario,
        bus: Bus,
        keys: SwarmKeys,
        every_ticks: int,
        noise_std_m: float = 0.0,
        seed: int = 0,
        late_s: Callable[[float], float] = lambda _t: 0.0,
        sensor_buses: Mapping[int, Bus | LinkBus] | None = None,
        reported: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        self.n, self.m = scenario.n, scenario.m
        self.bus, self.keys, self.every = bus, keys, max(1, every_ticks)
        self.scenario = scenario
        self.observers = [t.observed_by for t in scenario.targets]
        # The sensor model follows the membership: a target whose observers all left is
        # seen by the follower agents.membership.ring re-assigns it to, as the followers expect.
        self.liveness = MembershipWatch(bus, keys, self.n)
        self.members: frozenset[int] = frozenset(range(self.n))
        self.hold = MemberHold(decided=self.members)  # as the followers hold a far side
        self.noise_std_m = noise_std_m
        self.rng = np.random.default_rng(seed)
        self.truth_stamper = Stamper("sim-0", bus.now_s)
        self.sensor_stampers = [Stamper("sim-0", bus.now_s) for _ in range(self.n)]
        self.truth_out = bus.declare_publisher(keys.truth(), Congestion.DROP)
        links = sensor_buses or {}  # follower -> the bus of its host's sensor link
        self.sensor_out = [links.get(i, bus).declare_publisher(keys.sensor_targets(i),
                                                                 Congestion.DROP)
                           for i in range(self.n)]
        self.ticks = 0
        # How far the real clock is past the state's boot time when the hook runs: the
        # state is stamped with the time it is true, not with when it was published, so a
        # late tick does not make the followers' finite-difference velocities jump.
        self.late_s = late_s
        # [sensing] (agents.weather.target_sensor); None: every observer sees its targets exactly.
        cfg = scenario.sensing
        self.limited = None if cfg is None or cfg.is_perfect else TargetSensor(cfg)
        self.reported = reported or (lambda pos_ned: pos_ned)  # the vehicles' GPS fixes

    def __call__(self, sim_time_s: float, state: FleetState) -> None:
        self.ticks += 1
        if self.ticks % self.every:
            return
        now = self.bus.now_s() - max(0.0, self.late_s(sim_time_s))
        pos = ned_to_enu(state.pos_ned_m)
        vel = ned_to_enu(state.vel_ned_m_s)
        truth = TruthSnapshot(
            self.truth_stamper.header(now),
            sim_time_s,
            tuple(vec3(p) for p in pos[: self.n]),
            tuple(vec3(v) for v in vel[: self.n]),
            tuple(vec2(p[:2]) for p in pos[self.n :]),
            tuple(vec2(v[:2]) for v in vel[self.n :]),
        )
        self.truth_out.put(encode(truth))
        self._follow_membership(now)
        if self.limited is not None:
            self._sense(self.limited, now, state)
            return
        noise_std = self.noise_std_m if self.noise_std_m > 0.0 else None
        for j, observers in enumerate(self.observers):
            for i in observers:
                seen = pos[self.n + j, :2]
                if noise_std is not None:
                    seen = seen + self.rng.normal(0.0, noise_std, 2)
                msg = TargetObservation(
                    self.sensor_stampers[i].header(now), i, j, vec2(seen), now, noise_std
                )
                self.sensor_out[i].put(encode(msg))

    def _sense(self, sensor: TargetSensor, now_s: float, state: FleetState) -> None:
        """The limited sensor's observations: latent, missed beyond its range or by chance."""
        true_s, pos, fixes = sensor.remember(now_s, ned_to_enu(state.pos_ned_m),
                                             ned_to_enu(self.reported(state.pos_ned_m)))
        std = sensor.cfg.noise_std_m or None
        for j, observers in enumerate(self.observers):
            for i in observers:
                seen = sensor.observe(pos[i, :2], fixes[i, :2], pos[self.n + j, :2])
                if seen is None:
                    continue
                msg = TargetObservation(
                    self.sensor_stampers[i].header(now_s), i, j, vec2(seen), true_s, std)
                self.sensor_out[i].put(encode(msg))

    def _follow_membership(self, now_s: float) -> None:
        members = self.hold.members(self.liveness.members(now_s), now_s)
        if members and members != self.members:
            self.members = members
            self.observers = list(membership(self.scenario, members).observers)
            log.info("members %s: observers %s", sorted(members), self.observers)

    def sensing_counters(self) -> dict[str, int]:
        """Observations the limited sensor did not make (none without `[sensing]`)."""
        return {} if self.limited is None else dict(self.limited.counters)

    def close(self) -> None:
        self.liveness.close()
        for pub in [self.truth_out, *self.sensor_out]:
            pub.close()


def sensor_every_ticks(tick_hz: float, sensor_hz: float) -> int:
    """Ticks between observations: the most that still gives at least `sensor_hz` (a 20-Hz
    swarm on a 50-Hz simulator: every 2nd tick, 25 Hz), and never below one tick.  Each
    observation is a message to a follower and the recorder, so one faster than the
    followers' loop is read by nobody (ring64 at 20 Hz: 3 200 of them a second)."""
    return max(1, math.floor(tick_hz / sensor_hz + 1e-9))


def wrong_key_senders(counters: Mapping[str, int], n: int) -> dict[str, int]:
    """The agents whose vehicle keys signed frames sent to other vehicles, as the refusals
    of deploy.report.refusals name senders: `rejected_from_<agent>` (one counter per key holder:
    at most one per vehicle)."""
    prefix = "signing_wrong_key_vehicle_"
    return {f"rejected_from_{agent_of_vehicle(int(k[len(prefix):]), n)}": v
            for k, v in counters.items() if k.startswith(prefix) and k[len(prefix):].isdigit()}


MAX_DEFAULT_TICK_HZ = 50.0


def sim_tick_hz(control_hz: float) -> float:
    """The simulator's default tick rate for a swarm whose loop runs at `control_hz`: the
    largest whole multiple of it not above 50 Hz (50 Hz for faster loops, as before).

    On a whole multiple, position telemetry and target observations come exactly once per
    control period.  ring64's 20 Hz on 50 Hz ticks got them every 40 or 60 ms (2.5 ticks)
    and 25 observations a second per follower; on 40 Hz ticks, every 50 ms and 20 a second:
    a fifth fewer simulator ticks and sensor messages (simulator late ticks 22-32 % against
    27-60 % in alternate runs; BENCHMARKS.md).  The vehicle model is an
    exact discretisation, so a coarser tick does not change its dynamics."""
    if control_hz >= MAX_DEFAULT_TICK_HZ:
        return MAX_DEFAULT_TICK_HZ
    return control_hz * math.floor(MAX_DEFAULT_TICK_HZ / control_hz + 1e-9)


@dataclass(frozen=True)
class SwarmSimOptions:
    """The simulator process's command line (None rates: from the scenario)."""

    bus: BusOptions
    rate_hz: float | None = None
    telemetry_hz: float | None = None
    sensor_hz: float | None = None
    noise_std_m: float = 0.0
    seed: int = 0
    base_port: int = 14580
    mav_host: str = "127.0.0.1"
    send_base_port: int = 14540
    signing_secret: str | None = None  # the run's MAVLink secret: a key per vehicle
    sensor_links: tuple[str, ...] = ()  # --sensor-link ENDPOINT=I,J (sim_backend.sensor_links)
    mav_peers: tuple[str, ...] = ()  # --mav-peers: each vehicle's agent's address
    gust_windows: tuple[float, ...] | None = None  # --gust-window: the launcher's, in order

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> SwarmSimOptions:
        return cls(BusOptions.from_namespace(args), args.rate_hz, args.telemetry_hz,
                   args.sensor_hz, args.noise_std_m, args.seed, args.base_port, args.mav_host,
                   args.send_base_port, args.signing_secret, tuple(args.sensor_link),
                   parse_peer_hosts(args.mav_peers),
                   None if args.gust_window is None else tuple(args.gust_window))


def sim_config(opts: SwarmSimOptions, scenario: Scenario, tick_hz: float) -> SimConfig:
    """The vehicles' MAVLink side as the command line sets it."""
    return SimConfig(
        rate_hz=tick_hz,
        telemetry_hz=opts.telemetry_hz or tick_hz,
        flavour=scenario.vehicle.flavour,
        host=opts.mav_host,
        listen_base_port=opts.base_port,
        send_base_port=opts.send_base_port,
        signing_secret=None if opts.signing_secret is None else load_key(opts.signing_secret),
        peer_hosts=opts.mav_peers,
    )



def listen_for_wind(schedule: WindSchedule | None) -> None:
    """The launcher opens and closes the timeline's gust windows by signals
    (deploy.launch.fault_injector); the next tick flies the new strength.  Without windows
    a signal is logged and ignored: its default action would end the simulator."""
    if schedule is None:
        def ignored(*_a: object) -> None:
            log.warning("a gust window was signalled, but this simulator was given none")

        signal.signal(wind_begin_signal(), ignored)
        signal.signal(wind_end_signal(), ignored)
        return
    signal.signal(wind_begin_signal(), lambda *_a: schedule.begin())
    signal.signal(wind_end_signal(), lambda *_a: schedule.end())


def run(opts: SwarmSimOptions) -> int:
    scenario = load_run_scenario(opts.bus)
    tick_hz = opts.rate_hz or sim_tick_hz(scenario.run.rate_hz)
    cfg = sim_config(opts, scenario, tick_hz)
    keys = SwarmKeys(opts.bus.swarm)
    links = [parse_sensor_link(text, scenario.n) for text in opts.sensor_links]
    with stop_on_signals() as stop, open_bus(opts.bus, scenario.network) as bus, \
            sensor_buses(links, opts.bus, scenario.network) as linked:
        spawn = spawn_points_ned(scenario)
        weather = weather_of(scenario, len(spawn), opts.gust_windows)
        listen_for_wind(None if weather is None else weather.schedule)
        sim = Simulator(spawn, scenario.vehicle, scenario.home, cfg, weather=weather)
        sensor = SensorPublisher(
            scenario, bus, keys,
            sensor_every_ticks(tick_hz, opts.sensor_hz or scenario.run.rate_hz),
            opts.noise_std_m, opts.seed, late_s=lambda t: sim.boot_time_s() - t,
            sensor_buses=linked, reported=None if weather is None else weather.reported_ned)
        status = StatusReporter(bus, keys, "sim", 0)
        sim.on_tick.append(sensor)

        def loop_counters() -> dict[str, int]:
            st = sim.stats
            return {"ticks": st.ticks, "overruns": st.overruns, "catch_ups": st.catch_ups,
                    "caught_up_ticks": st.caught_up_ticks, "resyncs": st.resyncs,
                    **dict(sim.counters), **wrong_key_senders(sim.counters, scenario.n),
                    **sensor.liveness.counters(), **sensor.sensing_counters(),
                    "sensing_link_dropped": sum(b.dropped for b in set(linked.values()))}

        def report(_t: float, _s: FleetState) -> None:
            if status.due():
                status.publish(extra=loop_counters())

        sim.on_tick.append(report)
        token = bus.declare_token(keys.alive("sim", 0))
        status.set("running")
        mark("linked")
        log_phases("sim")
        try:
            stats = sim.run(lambda: stop.raised)
        finally:
            token.close()
            sensor.close()
            sim.close()
        status.set("done", extra=loop_counters())
    log.info("simulator stopped at t=%.1f s: ticks=%d overruns=%d catch-ups=%d (%d ticks) %s",
             sim.sim_time_s, stats.ticks, stats.overruns, stats.catch_ups,
             stats.caught_up_ticks, dict(sim.counters))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="enclose-swarm-sim", description=__doc__)
    add_bus_arguments(parser)
    parser.add_argument("--rate-hz", type=float, default=None,
                        help="simulation tick rate (default: the largest whole multiple of "
                        "the scenario's control rate not above 50 Hz)")
    # Each agent asks its vehicle down to its own loop rate (agents.shell.vehicle_loop).
    parser.add_argument("--telemetry-hz", type=float, default=None,
                        help="default rate of the position streams (default: the tick rate)")
    parser.add_argument(
        "--sensor-hz",
        type=float,
        default=None,
        help="rate of truth snapshots and target observations (default: the scenario's "
        "control rate, [run] rate_hz)",
    )
    parser.add_argument(
        "--noise-std-m",
        type=float,
        default=0.0,
        help="std of Gaussian noise added to target observations",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the observation noise")
    parser.add_argument("--sensor-link", action="append", default=[], metavar="ENDPOINT=I,J",
                        help="publish the observations of followers I,J (0-based) through a "
                        "session to this endpoint: another host's sensing endpoint")
    parser.add_argument("--gust-window", type=float, action="append", default=None,
                        metavar="STD_M_S", help="the gusts' strength in each of the timeline's "
                        "wind windows, in time order (the launcher opens and closes them)")
    parser.add_argument("--base-port", type=int, default=14580)
    parser.add_argument("--mav-host", default="127.0.0.1", metavar="ADDR",
                        help="address the vehicles listen on (another host's agents: its "
                        "own address, or 0.0.0.0); telemetry also goes to whoever sends")
    parser.add_argument("--send-base-port", type=int, default=14540)
    parser.add_argument("--mav-peers", default=None, metavar="ADDR,ADDR,...",
                        help="the address of each vehicle's agent, in vehicle order: vehicle i "
                        "then hears (ADDR_i, send base + i) alone and sends its telemetry "
                        "there (default: anyone, as PX4 SITL)")
    parser.add_argument("--signing-secret", default=None, metavar="FILE",
                        help="the run's 32-byte MAVLink secret: each vehicle enforces signing "
                        "with its own key derived from it (agents.mavlink.signing)")
    return process_main(parser, argv, SwarmSimOptions.from_namespace, run, lambda _o: "sim")


if __name__ == "__main__":
    sys.exit(main())
