"""The simulator process's one loop: fixed-rate ticks over many vehicles, each a MAVLink system.

The backend owns simulated time: `sim_time_s` advances by exactly one tick per
step.  Real-time pacing reads an injectable clock; `step_once()` advances one tick
without waiting, so tests can drive the simulator without sleeping.  Hooks in
`on_tick` see every tick's state (a future Zenoh publisher attaches here).
"""

from __future__ import annotations

import logging
import selectors
import socket
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from agents.errors import SimulatorError
from agents.frames import enu_to_ned
from agents.mavlink.modes import FLAVOURS
from agents.mavlink.signing import SignatureVerifier
from agents.scenario import HomeConfig, Scenario, VehicleConfig
from sim_backend import model
from sim_backend.autopilot import Autopilot
from sim_backend.endpoint import VehicleEndpoint
from sim_backend.params import ParamStore, default_params
from sim_backend.telemetry import Row

log = logging.getLogger(__name__)
TickHook = Callable[[float, model.FleetState], None]
RESYNC_TICKS = 5
MAX_VEHICLES = 255


@dataclass(frozen=True)
class SimConfig:
    """Loop rate and PX4 SITL ports: vehicle i listens on listen_base+i, sends to send_base+i."""

    rate_hz: float = 50.0
    telemetry_hz: float = 50.0
    flavour: str = "px4"
    host: str = "127.0.0.1"
    listen_base_port: int = 14580
    send_base_port: int = 14540
    signing_key: bytes | None = None  # vehicles enforce MAVLink 2 signing with this key


@dataclass(frozen=True)
class Snapshot:
    """A copy of every vehicle's state at one tick, safe to keep."""

    sim_time_s: float
    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray
    yaw_rad: np.ndarray
    armed: tuple[bool, ...]
    modes: tuple[str, ...]


@dataclass
class LoopStats:
    ticks: int = 0
    overruns: int = 0
    resyncs: int = 0
    max_late_s: float = 0.0


def spawn_points_ned(scenario: Scenario) -> np.ndarray:
    """Followers then targets, on the ground at their scenario (x, y), in NED."""
    xy = list(scenario.follower_pos_m) + [t.initial_pos_m for t in scenario.targets]
    return enu_to_ned(np.array([[x, y, 0.0] for x, y in xy]))


def grid_spawn_ned(n: int, spacing_m: float = 5.0) -> np.ndarray:
    side = max(1, int(np.ceil(np.sqrt(n))))
    return np.array([[(k // side) * spacing_m, (k % side) * spacing_m, 0.0] for k in range(n)])


class Simulator:
    """N vehicles (sysid i+1) stepped together, each behind its own UDP socket."""

    def __init__(self, spawn_ned_m: np.ndarray, vehicle: VehicleConfig, home: HomeConfig,
                 cfg: SimConfig, clock: Callable[[], float] = time.monotonic) -> None:
        if cfg.flavour not in FLAVOURS:
            raise SimulatorError(f"flavour must be one of {FLAVOURS}, got {cfg.flavour!r}")
        if not 1 <= len(spawn_ned_m) <= MAX_VEHICLES:
            raise SimulatorError(f"1..{MAX_VEHICLES} vehicles per process (sysid i+1 is one byte)")
        if not 0 < cfg.telemetry_hz <= cfg.rate_hz:
            raise SimulatorError("telemetry rate must be > 0 and not above the tick rate")
        self.cfg = cfg
        self.dt_s = 1.0 / cfg.rate_hz
        self.params = model.ModelParams.from_vehicle(vehicle)
        self.state = model.FleetState.on_ground(spawn_ned_m)
        self.command = model.FleetCommand.idle(self.state.n)
        self.sim_time_s = 0.0
        self.counters: Counter[str] = Counter()
        # Received messages by "TYPE:outcome" (answered, handled, ignored, refused, ...).
        self.messages: Counter[str] = Counter()
        self.stats = LoopStats()
        self.on_tick: list[TickHook] = []
        self._clock = clock
        self._selector = selectors.DefaultSelector()
        self.endpoints: list[VehicleEndpoint] = []
        self._rows: list[Row] = []
        try:
            for i in range(self.state.n):
                self.endpoints.append(self._open_endpoint(i, vehicle, home))
        except OSError as exc:
            self.close()
            raise SimulatorError(f"cannot bind vehicle {len(self.endpoints)}: {exc}") from exc
        self._rows = self._build_rows()

    def _open_endpoint(self, i: int, vehicle: VehicleConfig, home: HomeConfig) -> VehicleEndpoint:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            port = self.cfg.listen_base_port + i if self.cfg.listen_base_port else 0
            sock.bind((self.cfg.host, port))
            sock.setblocking(False)
        except OSError:
            sock.close()
            raise
        flavour, sysid = self.cfg.flavour, i + 1
        store = ParamStore(flavour, default_params(flavour, sysid, vehicle))
        spawn = tuple(float(v) for v in self.state.pos_ned_m[i])
        autopilot = Autopilot(flavour, home.alt_m, home_ned_m=(spawn[0], spawn[1], spawn[2]))
        dest = (self.cfg.host, self.cfg.send_base_port + i)
        endpoint = VehicleEndpoint(sysid, sock, dest, autopilot, store, home,
                                   self.cfg.telemetry_hz, self.counters, index=i, tick_s=self.dt_s,
                                   messages=self.messages)
        if self.cfg.signing_key is not None:
            endpoint.verifier = SignatureVerifier(self.cfg.signing_key)
        self._selector.register(sock, selectors.EVENT_READ, i)
        return endpoint

    @property
    def n(self) -> int:
        return self.state.n

    def listen_ports(self) -> list[int]:
        return [ep.sock.getsockname()[1] for ep in self.endpoints]

    def close(self) -> None:
        for ep in self.endpoints:
            self._selector.unregister(ep.sock)
            ep.sock.close()
        self.endpoints = []
        self._selector.close()

    # ---- one tick -----------------------------------------------------------------------
    def step_once(self) -> None:
        """Receive what is queued, then advance the fleet by one tick and send telemetry."""
        self.receive_until(-1.0)
        self._advance()

    def _advance(self) -> None:
        now = self.sim_time_s
        for i, ep in enumerate(self.endpoints):
            ap = ep.autopilot
            if ap.armed:
                row = self._rows[i]
                failsafes = ap.failsafes
                ap.update(now, row.pos, row.landed)
                self.counters["failsafes"] += ap.failsafes - failsafes
            if ap.dirty:
                self._write_control(i, ap)
        self.state = model.step(self.state, self.command, self.params, self.dt_s)
        self.sim_time_s = round(self.sim_time_s + self.dt_s, 9)
        self._rows = self._build_rows()
        for i, ep in enumerate(self.endpoints):
            try:
                ep.telemetry(self.sim_time_s, self._rows[i])
            except Exception:  # one vehicle's bad state must not stop the others
                self.counters["telemetry_errors"] += 1
                if self.counters["telemetry_errors"] <= 5:
                    log.exception("vehicle %d: telemetry failed", ep.sysid)
        for hook in self.on_tick:
            hook(self.sim_time_s, self.state)
        self.stats.ticks += 1

    def _write_control(self, i: int, ap: Autopilot) -> None:
        row = ap.control()
        c = self.command
        c.motors_on[i] = row.motors_on
        c.pos_axis[i] = row.pos_axis
        c.pos_sp_ned_m[i] = row.pos_sp_ned_m
        c.vel_sp_ned_m_s[i] = row.vel_sp_ned_m_s
        c.yaw_mode[i] = row.yaw_mode
        c.yaw_sp_rad[i] = row.yaw_sp_rad
        c.yaw_rate_sp_rad_s[i] = row.yaw_rate_sp_rad_s

    def _build_rows(self) -> list[Row]:
        s = self.state
        roll, pitch = model.tilt_rad(s.acc_ned_m_s2, s.yaw_rad)
        on_ground = model.landed(s).tolist()
        ms = int(self.sim_time_s * 1000.0)
        return [Row(ms, tuple(p), tuple(v), r, q, y, w, g)
                for p, v, r, q, y, w, g in zip(s.pos_ned_m.tolist(), s.vel_ned_m_s.tolist(),
                                                roll.tolist(), pitch.tolist(), s.yaw_rad.tolist(),
                                                s.yaw_rate_rad_s.tolist(), on_ground, strict=True)]

    def receive_until(self, deadline: float) -> None:
        """Handle datagrams until the clock reaches `deadline` (past deadline: what is queued).

        The clock is checked after each socket, so a burst of datagrams delays the next
        tick by at most one socket's worth of work; the rest waits in the socket buffers.
        """
        while True:
            remaining = deadline - self._clock()
            events = self._selector.select(max(0.0, remaining))
            for key, _ in events:
                self._drain(key.data)
                if deadline >= 0.0 and self._clock() >= deadline:
                    return
            if not events or remaining <= 0.0:
                return

    def _drain(self, i: int) -> None:
        ep = self.endpoints[i]
        for _ in range(16):  # bounded so one chatty peer cannot starve the others
            try:
                data, addr = ep.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                self.counters["rx_errors"] += 1
                return
            ep.on_datagram(data, addr, self.sim_time_s, self._rows[i])

    # ---- real time ----------------------------------------------------------------------
    def run(self, should_stop: Callable[[], bool], max_ticks: int | None = None) -> LoopStats:
        """Tick at rate_hz in real time until should_stop() or max_ticks; counts overruns."""
        start = self._clock()
        k = 0
        while not should_stop() and (max_ticks is None or k < max_ticks):
            self._advance()
            k += 1
            deadline = start + k * self.dt_s
            now = self._clock()
            if now > deadline:
                self.stats.overruns += 1
                self.stats.max_late_s = max(self.stats.max_late_s, now - deadline)
                if now - deadline > RESYNC_TICKS * self.dt_s:
                    start = now - k * self.dt_s
                    self.stats.resyncs += 1
                # Even when late, serve commands and setpoints for a fifth of a tick.
                deadline = now + 0.2 * self.dt_s
            self.receive_until(deadline)
        return self.stats

    def snapshot(self) -> Snapshot:
        s = self.state
        return Snapshot(self.sim_time_s, s.pos_ned_m.copy(), s.vel_ned_m_s.copy(),
                        s.yaw_rad.copy(), tuple(ep.autopilot.armed for ep in self.endpoints),
                        tuple(ep.autopilot.mode for ep in self.endpoints))
