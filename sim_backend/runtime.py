"""The simulator process's one loop: fixed-rate ticks over many vehicles, each a MAVLink system.

The backend owns simulated time: `sim_time_s` advances by exactly one tick per
step.  Real-time pacing reads an injectable clock and sleep; `step_once()` advances one
tick without waiting, so tests can drive the simulator without sleeping.  Hooks in
`on_tick` see every tick's state (the swarm's truth and sensor publisher attaches here).

While pacing, the loop sleeps to each tick and then reads what arrived meanwhile: one
wake-up a tick, not one per datagram.  Each wake-up costs several times the code's warm
cost (BENCHMARKS.md, "What a tick costs"), and a swarm's agents send at their own phases
over the tick: waking per datagram cost the simulator a quarter of its CPU in the paper's
case and a sixth with 64 vehicles.  A setpoint still acts at the tick after it
arrived, as before; what waits is a reply (a command's ACK, a parameter) by up to a tick,
as with an autopilot that serves its links from its main loop.  TIMESYNC alone needs the
arrival time, and takes it from the kernel (sim_backend.arrival).

While `run()` paces, the vehicles' boot clock is locked to the real clock as a real
autopilot's is: a late tick (a scheduling stall, a SIGSTOP of this process) is caught
up by integrating the missed time in one-tick physics sub-steps, never dropped, and
what arrived meanwhile is stamped with the real boot time, so that the simulator's own
stall does not trip the vehicles' setpoint-loss failsafe.  Telemetry and hooks run
once per real tick, not once per sub-step: a caught-up burst sends nothing extra.
"""

from __future__ import annotations

import logging
import selectors
import socket
import time
from collections import Counter
from collections.abc import Callable

import numpy as np

from agents.mavlink.modes import FLAVOURS
from agents.scenario.model import HomeConfig, VehicleConfig
from errors import SimulatorError
from sim_backend import kinematics
from sim_backend.arrival import ANCILLARY_BYTES, held_s, stamp_arrivals
from sim_backend.autopilot import Autopilot, ControlRow
from sim_backend.clock_services import ClockService
from sim_backend.endpoint import VehicleEndpoint
from sim_backend.params import ParamStore, default_params
from sim_backend.sim_values import LoopStats, SimConfig, Snapshot
from sim_backend.sim_values import grid_spawn_ned as grid_spawn_ned  # re-exported (importers)
from sim_backend.sim_values import spawn_points_ned as spawn_points_ned  # re-exported
from sim_backend.telemetry import Row
from sim_backend.vehicle_weather import SimWeather

log = logging.getLogger(__name__)
TickHook = Callable[[float, kinematics.FleetState], None]
MAX_CATCHUP_S = 30.0  # a longer stall (a debugger, a laptop lid) is dropped, counted, logged
MAX_VEHICLES = 255
QUEUED_ROUNDS = 16  # rounds over the ready sockets when taking what is queued


def _reachable(host: str) -> str:
    """Where telemetry to `host`'s own machine goes: a wildcard bind address names no peer
    (0.0.0.0 reaches this machine as 127.0.0.1 does), so that a local agent sending from
    127.0.0.1 is one destination, not two, and never gets each datagram twice (the second
    a replay to its verifier)."""
    return "127.0.0.1" if host in ("0.0.0.0", "") else host


class Simulator:
    """N vehicles (sysid i+1) stepped together, each behind its own UDP socket."""

    def __init__(self, spawn_ned_m: np.ndarray, vehicle: VehicleConfig, home: HomeConfig,
                 cfg: SimConfig, clock: Callable[[], float] = time.monotonic,
                 weather: SimWeather | None = None,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        if cfg.signing_secret is not None and cfg.signing_key is not None:
            raise SimulatorError("signing: a run secret (a key per vehicle) or one key, not both")
        if cfg.flavour not in FLAVOURS:
            raise SimulatorError(f"flavour must be one of {FLAVOURS}, got {cfg.flavour!r}")
        if not 1 <= len(spawn_ned_m) <= MAX_VEHICLES:
            raise SimulatorError(f"1..{MAX_VEHICLES} vehicles per process (sysid i+1 is one byte)")
        if cfg.peer_hosts and len(cfg.peer_hosts) != len(spawn_ned_m):
            raise SimulatorError(f"peer_hosts: one address per vehicle ({len(spawn_ned_m)}), "
                                 f"got {len(cfg.peer_hosts)}")
        if not 0 < cfg.telemetry_hz <= cfg.rate_hz:
            raise SimulatorError("telemetry rate must be > 0 and not above the tick rate")
        self.cfg = cfg
        self.weather = weather  # None: still air and exact positions (sim_backend.vehicle_weather)
        self.dt_s = 1.0 / cfg.rate_hz
        self.params = kinematics.ModelParams.from_vehicle(vehicle)
        self.state = kinematics.FleetState.on_ground(spawn_ned_m)
        self.command = kinematics.FleetCommand.idle(self.state.n)
        self.sim_time_s = 0.0
        self.counters: Counter[str] = Counter()
        # Received messages by "TYPE:outcome" (answered, handled, ignored, refused, ...).
        self.messages: Counter[str] = Counter()
        self.stats = LoopStats()
        self.on_tick: list[TickHook] = []
        self._clock, self._sleep = clock, sleep
        self._origin_s: float | None = None  # clock reading at boot time 0 while run() paces
        self._selector = selectors.DefaultSelector()
        self._resting: list[int] = []  # vehicles off the selector: their tick's budget is spent
        self.endpoints: list[VehicleEndpoint] = []
        self.clocks: list[ClockService] = []
        self._rows: list[Row] = []
        try:
            for i in range(self.state.n):
                self.endpoints.append(self._open_endpoint(i, vehicle, home))
        except OSError as exc:
            self.close()
            raise SimulatorError(f"cannot bind vehicle {len(self.endpoints)}: {exc}") from exc
        self._rows = self._build_rows()
        self._keys = {i + 1: ep.verifier.key for i, ep in enumerate(self.endpoints)
                      if ep.verifier is not None}

    def _open_endpoint(self, i: int, vehicle: VehicleConfig, home: HomeConfig) -> VehicleEndpoint:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        dest = (self.cfg.peer_hosts[i] if self.cfg.peer_hosts else _reachable(self.cfg.host),
                self.cfg.send_base_port + i)
        try:
            port = self.cfg.listen_base_port + i if self.cfg.listen_base_port else 0
            sock.bind((self.cfg.host, port))
            if self.cfg.peer_hosts:  # its agent's datagrams alone (SimConfig.peer_hosts)
                sock.connect(dest)
            sock.setblocking(False)
            stamp_arrivals(sock)
        except OSError:
            sock.close()
            raise
        flavour, sysid = self.cfg.flavour, i + 1
        store = ParamStore(flavour, default_params(flavour, sysid, vehicle))
        spawn = tuple(float(v) for v in self.state.pos_ned_m[i])
        autopilot = Autopilot(flavour, home.alt_m, home_ned_m=(spawn[0], spawn[1], spawn[2]))
        endpoint = VehicleEndpoint(sysid, sock, dest, autopilot, store, home,
                                   self.cfg.telemetry_hz, self.counters, index=i, tick_s=self.dt_s,
                                   messages=self.messages)
        key = self.cfg.vehicle_key(sysid)
        if key is not None:  # the others' keys: built once every endpoint is open
            endpoint.enforce_signing(key, key_of_vehicle=lambda s: self._keys.get(s))
        self._selector.register(sock, selectors.EVENT_READ, i)
        self.clocks.append(ClockService(
            endpoint.mav, endpoint.send_to, self.boot_time_s, time.time, self.counters,
            held_s=lambda: held_s(endpoint.arrival, time.time())).attach(endpoint))
        return endpoint

    @property
    def n(self) -> int:
        return self.state.n

    def listen_ports(self) -> list[int]:
        return [ep.sock.getsockname()[1] for ep in self.endpoints]

    def close(self) -> None:
        for i, ep in enumerate(self.endpoints):
            if i not in self._resting:
                self._selector.unregister(ep.sock)
            ep.sock.close()
        self.endpoints = []
        self.clocks = []
        self._selector.close()

    # ---- one tick -----------------------------------------------------------------------
    def step_once(self) -> None:
        """Receive what is queued, then advance the fleet by one tick and send telemetry."""
        self.receive_until(-1.0)
        self._advance()

    def _advance(self) -> None:
        now = self.sim_time_s
        changed: list[tuple[int, ControlRow]] = []
        for i, ep in enumerate(self.endpoints):
            ap = ep.autopilot
            if ap.armed:
                row = self._rows[i]
                failsafes = ap.failsafes
                ap.update(now, row.pos, row.landed)
                self.counters["failsafes"] += ap.failsafes - failsafes
            if ap.dirty:
                changed.append((i, ap.control()))
        if changed:
            self._write_control(changed)
        self.state = self._step()
        self.sim_time_s = round(self.sim_time_s + self.dt_s, 9)
        self._rows = self._build_rows()
        for i, ep in enumerate(self.endpoints):
            try:
                ep.telemetry(self.sim_time_s, self._rows[i])
                self.clocks[i].due(ep.default_dest)
            except Exception:  # one vehicle's bad state must not stop the others
                self.counters["telemetry_errors"] += 1
                if self.counters["telemetry_errors"] <= 5:
                    log.exception("vehicle %d: telemetry failed", ep.sysid)
        for hook in self.on_tick:
            hook(self.sim_time_s, self.state)
        self.stats.ticks += 1
        self._new_budgets()

    def _step(self) -> kinematics.FleetState:
        if self.weather is None:
            return kinematics.step(self.state, self.command, self.params, self.dt_s)
        return self.weather.step(self.state, self.command, self.params, self.dt_s)

    def _new_budgets(self) -> None:
        """A new tick: every vehicle's receive budget afresh (first the datagram the last
        one had no room for), every socket read again."""
        self._take_carried()
        for i in self._resting:
            self._selector.register(self.endpoints[i].sock, selectors.EVENT_READ, i)
        self._resting.clear()

    def _take_carried(self) -> None:
        """Handle the datagrams the last tick read but had no budget left to parse (each
        gate then starts a new tick): at a tick's end, and when the run stops, so that a
        datagram taken off its socket is never lost."""
        for i, ep in enumerate(self.endpoints):
            carried = ep.gate.new_tick()
            if carried is not None and carried[1] is not None:
                ep.parse_datagram(carried[0], carried[1], self.boot_time_s(), self._rows[i])

    def _write_control(self, changed: list[tuple[int, ControlRow]]) -> None:
        """Changed control rows (every vehicle, while setpoints stream): one write per field."""
        idx = [i for i, _ in changed]
        rows = [row for _, row in changed]
        c = self.command
        c.motors_on[idx] = [row.motors_on for row in rows]
        c.pos_axis[idx] = [row.pos_axis for row in rows]
        c.pos_sp_ned_m[idx] = [row.pos_sp_ned_m for row in rows]
        c.vel_sp_ned_m_s[idx] = [row.vel_sp_ned_m_s for row in rows]
        c.yaw_mode[idx] = [row.yaw_mode for row in rows]
        c.yaw_sp_rad[idx] = [row.yaw_sp_rad for row in rows]
        c.yaw_rate_sp_rad_s[idx] = [row.yaw_rate_sp_rad_s for row in rows]

    def _build_rows(self) -> list[Row]:
        s = self.state
        roll, pitch = kinematics.tilt_rad(s.acc_ned_m_s2, s.yaw_rad)
        on_ground = kinematics.landed(s).tolist()
        ms = round(self.sim_time_s * 1000.0)
        pos = s.pos_ned_m if self.weather is None else self.weather.reported_ned(s.pos_ned_m)
        return [Row(ms, tuple(p), tuple(v), r, q, y, w, g)
                for p, v, r, q, y, w, g in zip(pos.tolist(), s.vel_ned_m_s.tolist(),
                                                roll.tolist(), pitch.tolist(), s.yaw_rad.tolist(),
                                                s.yaw_rate_rad_s.tolist(), on_ground, strict=True)]

    def receive_until(self, deadline: float) -> None:
        """Handle datagrams until the clock reaches `deadline` (past deadline: what is queued,
        in at most QUEUED_ROUNDS rounds).  One datagram per ready socket per round (the
        selector is level-triggered): no read ends in EAGAIN, a wasted system call, and a
        chatty peer gets no more turns than the others.  The clock is checked after each
        datagram; a burst waits in the socket buffers rather than delay the next tick."""
        rounds = 0
        while True:
            remaining = deadline - self._clock()
            events = self._selector.select(max(0.0, remaining))
            for key, _ in events:
                self._take(key.data)
                if deadline >= 0.0 and self._clock() >= deadline:
                    return
            rounds += 1
            if not events or (remaining <= 0.0 and rounds >= QUEUED_ROUNDS):
                return

    def _take(self, i: int) -> bool:
        """Handle one datagram of vehicle i's socket; False when none was queued or its
        budget for this tick is spent (its socket then rests off the selector until the
        next tick: the rest waits in its buffer, and a flood on one vehicle's port costs
        the simulator one budget a tick, agents.mavlink.rx_gate)."""
        ep = self.endpoints[i]
        if not ep.gate.open:
            if i not in self._resting:
                self._selector.unregister(ep.sock)
                self._resting.append(i)
            self.counters["mav_budget_spent"] += 1
            return False
        try:
            data, ep.arrival, _flags, addr = ep.sock.recvmsg(65535, ANCILLARY_BYTES)
        except (BlockingIOError, InterruptedError):
            return False
        except ConnectionRefusedError:  # a connected vehicle's agent not (yet) listening
            self.counters["peer_unreachable"] += 1
            return False
        except OSError:
            self.counters["rx_errors"] += 1
            return False
        ep.on_datagram(data, addr, self.boot_time_s(), self._rows[i])
        return True

    def _drain(self, i: int) -> None:
        while self._take(i):  # bounded by the vehicle's budget for the tick
            pass

    # ---- real time ----------------------------------------------------------------------
    def boot_time_s(self) -> float:
        """The vehicles' boot clock: real time since boot while run() paces, else sim time."""
        if self._origin_s is None:
            return self.sim_time_s
        return max(self.sim_time_s, self._clock() - self._origin_s)

    def run(self, should_stop: Callable[[], bool], max_ticks: int | None = None) -> LoopStats:
        """Tick at rate_hz in real time until should_stop() or max_ticks.

        Each tick sleeps until it is due, takes what arrived meanwhile, then advances, so the
        state sent with time_boot_ms t is the state at boot time t, sent at t (after that
        tick's datagrams are handled).  Late ticks catch up.
        """
        self._origin_s = self._clock() - self.sim_time_s
        k = 0
        try:
            while not should_stop() and (max_ticks is None or k < max_ticks):
                rest_s = self._origin_s + self.sim_time_s + self.dt_s - self._clock()
                if rest_s > 0.0:
                    self._sleep(rest_s)
                self.receive_until(-1.0)
                self._catch_up()
                self._advance()
                k += 1
                late_s = self._clock() - (self._origin_s + self.sim_time_s + self.dt_s)
                if late_s > 0.0:
                    self.stats.overruns += 1
                    self.stats.max_late_s = max(self.stats.max_late_s, late_s)
        finally:
            self._take_carried()
            self._origin_s = None
        return self.stats

    def _catch_up(self) -> None:
        """Integrate, in one-tick physics sub-steps, every tick but the last that is due."""
        assert self._origin_s is not None
        behind = int((self._clock() - self._origin_s - self.sim_time_s) / self.dt_s + 1e-6) - 1
        if behind <= 0:
            return
        # Everything that waited out the stall, on every socket, is taken now (stamped with
        # the boot time it is taken at): a setpoint sent in time must not count as missing.
        for i in range(self.n):
            self._drain(i)
        limit = int(MAX_CATCHUP_S / self.dt_s)
        if behind > limit:
            dropped_s = (behind - limit) * self.dt_s
            self._origin_s += dropped_s
            self.stats.resyncs += 1
            log.warning("simulator stalled %.1f s: dropped %.1f s of vehicle time",
                        (behind + 1) * self.dt_s, dropped_s)
            behind = limit
        self.stats.catch_ups += 1
        self.stats.caught_up_ticks += behind
        self.stats.max_late_s = max(self.stats.max_late_s, behind * self.dt_s)
        for _ in range(behind):  # the commands in force, as a real airframe flies them
            self.state = self._step()
            self.sim_time_s = round(self.sim_time_s + self.dt_s, 9)
        self._rows = self._build_rows()

    def snapshot(self) -> Snapshot:
        s = self.state
        return Snapshot(self.sim_time_s, s.pos_ned_m.copy(), s.vel_ned_m_s.copy(),
                        s.yaw_rad.copy(), tuple(ep.autopilot.armed for ep in self.endpoints),
                        tuple(ep.autopilot.mode for ep in self.endpoints))
