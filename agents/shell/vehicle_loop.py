"""The life of a process that flies one vehicle: bus, MAVLink, start-up, fixed-rate loop, stop."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Protocol

from agents.mavlink.adapter import AdapterConfig, MavlinkAdapter, VehicleState
from agents.mavlink.modes import HOLD_MODE, OFFBOARD_MODE
from agents.mavlink.offboard import OffboardKeeper
from agents.mavlink.signing_keys import load_key
from agents.mavlink.startup import StartupTimeouts, start_offboard
from agents.membership.liveness import StallGuard
from agents.scenario.model import Scenario
from agents.shell.phases import log_phases, mark
from agents.shell.process import (
    StatusReporter,
    StopFlag,
    Ticker,
    apply_agent_sched,
    open_bus,
    stop_on_signals,
)
from agents.shell.process_options import AgentOptions
from agents.shell.tick_cost import NoCost, TickCost, tick_cost
from errors import MavlinkError
from transport.bus import Bus, Token
from transport.key_exprs import SwarmKeys

log = logging.getLogger(__name__)


class VehicleNode(Protocol):
    status: StatusReporter
    cost: TickCost | NoCost  # the loop's phase marks (agents.shell.tick_cost)
    start_s: float | None
    stop_s: float

    def tick(self, now_s: float) -> None: ...

    def counters(self) -> dict[str, int]: ...

    def close(self) -> None: ...


NodeFactory = Callable[[Bus, MavlinkAdapter], VehicleNode]
RECOVER_AFTER_S = 0.5  # not flying our setpoints this long: start the vehicle up again
# An agent whose vehicle is on another host (`--mav-vehicle-host`) waits for its first
# HEARTBEAT as long as the launcher waits for the swarm (`enclose host --link-timeout`'s
# default), not the 10 s of a vehicle on its own host: the hosts are started apart, and
# the simulator's may come up a minute after the companion's (docs/multihost.md).
REMOTE_HEARTBEAT_S = 120.0


@dataclass
class VehicleWatch:
    """Says when the vehicle stopped flying our setpoints: disarmed or rebooted (a restarted
    simulator), or in a mode other than offboard/guided or the failsafe's hold.  Real
    autopilots never return to offboard by themselves, so the agent must start it up again.

    Silence is not such a sign: a start-up needs the vehicle's answers, and while it
    waits for them the loop stops, and with it the estimator the neighbours read.  So a
    silent vehicle is waited for (the loop ticks on and commands a hover) and judged by
    what it says when it is heard again: a rebooted one reports itself disarmed.  On a
    loaded machine, where a simulator can miss its telemetry for a second, starting up
    again on every silence kept 32 followers from ever forming their ring."""

    recover_after_s: float = RECOVER_AFTER_S
    since_s: float | None = None

    def lost(self, state: VehicleState, flavour: str | None, now_s: float) -> bool:
        # The failsafe's Hold of an armed vehicle is OffboardKeeper's: it asks for offboard
        # again without blocking the loop; a full start-up is for the rest (never a silent
        # one, whose state is from before the silence: see the class docstring).
        ok = state.armed and flavour is not None and \
            state.mode in (OFFBOARD_MODE[flavour], HOLD_MODE[flavour])
        if ok or not state.link_ok:
            self.since_s = None
            return False
        if self.since_s is None:
            self.since_s = now_s
        return now_s - self.since_s >= self.recover_after_s


def _start_again(mav: MavlinkAdapter, altitude_m: float, stop: StopFlag, who: str,
                 timeouts: StartupTimeouts) -> bool:
    """The start-up sequence again (it skips what is already done); False if stopped."""
    log.warning("%s: vehicle not flying our setpoints (armed=%s mode=%s link=%s): "
                "starting it up again", who, mav.state.armed, mav.state.mode,
                mav.state.link_ok)
    stop.interrupt = True
    try:
        start_offboard(mav, altitude_m, timeouts)
    except KeyboardInterrupt:
        return False
    except MavlinkError as exc:  # e.g. no heartbeat yet: try again after RECOVER_AFTER_S
        log.warning("%s: start-up failed, will retry: %s", who, exc)
    finally:
        stop.interrupt = False
    return not stop.raised


def _nothing() -> None:
    pass


def _declare_alive(bus: Bus, key: str, role: str) -> tuple[Token | StallGuard, Callable[[], None]]:
    """The process's token, and what its loop calls each iteration.  A follower's token is
    its membership: a StallGuard withdraws it while the loop is stuck
    (agents.membership.liveness)."""
    if role == "follower":
        guard = StallGuard(bus, key)
        return guard, guard.alive
    return bus.declare_token(key), _nothing


def adapter_config(opts: AgentOptions, vehicle: int) -> AdapterConfig:
    """The MAVLink link to vehicle `vehicle` as the command line sets it."""
    mav_opts = opts.vehicle
    cfg = AdapterConfig.px4_sitl(vehicle, mav_opts.mav_local_base, mav_opts.mav_vehicle_base)
    if mav_opts.mav_vehicle_host:  # a companion computer off the vehicle's host: it listens
        # on every address, so it hears its vehicle's alone (AdapterConfig.connect)
        cfg = replace(cfg, remote_host=mav_opts.mav_vehicle_host, local_host="0.0.0.0",
                      connect=True)
    if mav_opts.signing_key is not None:  # link id: the vehicle's number, one stream per agent
        cfg = replace(cfg, signing_key=load_key(mav_opts.signing_key),
                      signing_link_id=vehicle & 0xFF)
    return cfg


def fly(opts: AgentOptions, scenario: Scenario, role: str, vehicle: int,
        make_node: NodeFactory) -> int:
    """Take off, declare the process linked, tick until stopped; returns the exit code.
    `scenario` is the one the process loaded (with its command line's overrides)."""
    index = opts.index
    apply_agent_sched(scenario.network)
    # Position as often as the loop reads it, no more: each frame is a datagram to verify
    # and decode (a 20-Hz ring64 follower took 2.5 a tick at the 50 Hz default).
    timeouts = StartupTimeouts(telemetry_hz=scenario.run.rate_hz)
    if opts.vehicle.mav_vehicle_host:  # hosts are started apart (docs/multihost.md)
        timeouts = replace(timeouts, heartbeat_s=REMOTE_HEARTBEAT_S)
    stamps = role == "follower" and opts.bus.network.latency_stamps
    with stop_on_signals() as stop, open_bus(opts.bus, scenario.network, stamps) as bus, \
            MavlinkAdapter(adapter_config(opts, vehicle), bus.now_s) as mav:
        node = make_node(bus, mav)
        node.status.set("starting")
        mark("node")  # subscriptions, publishers and first status declared
        stop.interrupt = True
        try:
            start_offboard(mav, scenario.vehicle.altitude_m, timeouts, mark=mark)
        except KeyboardInterrupt:
            log.info("%s %d stopped during start-up", role, index)
            node.close()
            return 0
        stop.interrupt = False
        token, alive = _declare_alive(bus, SwarmKeys(opts.bus.swarm).alive(role, index), role)
        node.status.set("linked")
        mark("linked")
        log_phases(f"{role} {index}")
        period = 1.0 / scenario.run.rate_hz
        # Neighbouring followers tick half a period apart, the rest spread (Scenario.tick_phase).
        phase = period * scenario.tick_phase(index) if role == "follower" else 0.0
        # A node with work between ticks (the follower's estimator) does it in the wait.
        idle = getattr(node, "idle", None)
        ticker = Ticker(period, bus.now_s, phase_s=phase, sleep=idle or time.sleep)
        flight = Flight(node, mav, ticker, alive, stop, f"{role} {index}",
                        scenario.vehicle.altitude_m, timeouts)
        try:
            flight.run(bus.now_s)
        finally:
            token.close()
            node.close()
    return 0


@dataclass
class Flight:
    """The loop of a linked process, `run`: tick the node at its rate, keep the vehicle in
    offboard, start it up again when it stopped flying our setpoints, publish the status."""

    node: VehicleNode
    mav: MavlinkAdapter
    ticker: Ticker
    alive: Callable[[], None]
    stop: StopFlag
    who: str  # "follower 3"
    altitude_m: float
    timeouts: StartupTimeouts
    watch: VehicleWatch = field(default_factory=VehicleWatch)

    def __post_init__(self) -> None:
        self.keeper = OffboardKeeper(self.mav)

    def run(self, now_s: Callable[[], float]) -> None:
        node, ticker = self.node, self.ticker
        cost = node.cost = tick_cost()
        measuring = False  # the cost from the start word on: the steady stretch
        while not self.stop.raised and now_s() < node.stop_s:
            now = ticker.wait()
            cost.mark("wait")
            if not measuring and node.start_s is not None:
                measuring = True
                cost.begin()
            if self.watch.lost(self.mav.state, self.mav.flavour, now):
                if not self.recover():
                    break
                continue
            self.alive()
            node.tick(now)
            self.keeper.check(now)
            node.status.state = "running" if node.start_s is not None else "linked"
            if node.status.due():
                node.status.publish(extra=self.extra())
            cost.mark("loop")
        node.status.set("done", extra=self.extra())
        log.info("%s done: ticks=%d overruns=%d %s", self.who, ticker.ticks, ticker.overruns,
                 node.counters())

    def recover(self) -> bool:
        """The vehicle's start-up again, still a member meanwhile
        (agents.membership.liveness.StallGuard); False if the process was stopped during it."""
        self.node.status.counters["vehicle_restarts"] += 1
        self.mav.on_wait = self.heartbeat
        try:
            again = _start_again(self.mav, self.altitude_m, self.stop, self.who, self.timeouts)
        finally:
            self.mav.on_wait = None
        self.watch.since_s = None
        return again

    def heartbeat(self) -> None:
        self.alive()
        if self.node.status.due():
            self.node.status.publish(extra=self.extra())

    def extra(self) -> dict[str, int]:
        """The loop's and the adapter's counters beside the node's, for the status."""
        # What the adapter refused or dropped (signatures, flood): agents.mavlink.rx_gate.
        # Not "rx_": that prefix names a link's counters (deploy.recording.links).
        mav = self.mav
        signing = {k: v for k, v in mav.counters.items() if k.startswith(("signing_", "mav_"))}
        return {"overruns": self.ticker.overruns, "ticks": self.ticker.ticks,
                "offboard_requests": self.keeper.requests,
                **mav.clock_counters(), **signing, **self.node.counters()}
