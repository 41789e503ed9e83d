"""Blocking start-up helpers with explicit timeouts: heartbeat -> arm -> take-off -> offboard.

PX4:       arm, NAV_TAKEOFF (param7 = AMSL altitude), stream setpoints, DO_SET_MODE OFFBOARD.
ArduPilot: DO_SET_MODE GUIDED, arm, NAV_TAKEOFF (param7 = relative altitude), stream setpoints.
Commands are re-sent when no COMMAND_ACK arrives within `retry_s`, as SDKs do.

A command's timeout, and a mode's or a take-off's, counts only the time the vehicle is
heard (`HeardClock`): a vehicle whose telemetry stopped has not refused anything, it is
unheard (its radio dropped, or a starved simulator, as when 64 followers start on 2
cores and make ~2 100 TLS handshakes: followers gave up on take-off ACKs the simulator
had not had the CPU to send).  Silence has its own limit, `silent_s` per wait.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass

from agents.mavlink.adapter import MavlinkAdapter, VehicleState
from agents.mavlink.modes import ARDUPILOT, OFFBOARD_MODE, do_set_mode_params
from errors import CommandRejectedError, MavlinkError

log = logging.getLogger(__name__)

MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
MSG_HEARTBEAT = 0
MSG_ATTITUDE = 30
MSG_LOCAL_POSITION_NED = 32
MSG_GLOBAL_POSITION_INT = 33
MSG_HOME_POSITION = 242
ACCEPTED, TEMPORARILY_REJECTED, IN_PROGRESS = 0, 1, 5
ZERO = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class StartupTimeouts:
    heartbeat_s: float = 10.0
    position_s: float = 5.0
    command_s: float = 3.0
    takeoff_s: float = 60.0
    offboard_s: float = 5.0
    retry_s: float = 0.5
    heartbeat_request_s: float = 0.1  # HEARTBEAT asked for again (wait_heartbeat)
    stream_s: float = 0.5
    setpoint_hz: float = 20.0
    altitude_tolerance_m: float = 0.3
    telemetry_hz: float = 50.0
    silent_s: float = 30.0  # a wait that heard nothing from the vehicle this long fails
    # Streams the agent reads only at start-up (or not at all), asked down as a companion
    # computer does on PX4/ArduPilot; not off: a ground station on the vehicle still sees them.
    slow_telemetry_hz: float = 4.0


HEARD_WINDOW_S = 1.5  # before telemetry: any message this recent (1-Hz HEARTBEATs)


class HeardClock:
    """Seconds during which the vehicle was heard, since creation: its telemetry link up
    (`link_ok`) once it streams, any message within HEARD_WINDOW_S before; raises
    MavlinkError once it was unheard for more than `silent_s` in all."""

    def __init__(self, ad: MavlinkAdapter, silent_s: float, what: str) -> None:
        self.ad, self.silent_limit_s, self.what = ad, silent_s, what
        self._last_s = ad.clock()
        self.heard_s = self.silent_s = 0.0

    def __call__(self) -> float:
        now = self.ad.clock()
        step, self._last_s = max(0.0, now - self._last_s), now
        if self._heard(now):
            self.heard_s += step
        else:
            self.silent_s += step
            if self.silent_s > self.silent_limit_s:
                raise MavlinkError(f"vehicle {self.ad.sysid} unheard for "
                                   f"{self.silent_limit_s:.1f} s while waiting for {self.what}")
        return self.heard_s

    def _heard(self, now: float) -> bool:
        if self.ad.telemetry_seen:
            return self.ad.state.link_ok
        return now - self.ad.heard_s < HEARD_WINDOW_S


def wait_until(ad: MavlinkAdapter, ok: Callable[[VehicleState], bool], timeout_s: float,
               what: str, keepalive_hz: float = 0.0,
               clock: Callable[[], float] | None = None) -> VehicleState:
    """Poll until ok(state); streams zero-velocity setpoints at keepalive_hz meanwhile.

    `clock` (default: the adapter's) is what the timeout counts: a HeardClock stops while
    the vehicle is unheard."""
    elapsed = clock or ad.clock
    deadline = elapsed() + timeout_s
    next_keepalive = ad.clock()
    while True:
        state = ad.poll()
        if ok(state):
            return state
        if elapsed() >= deadline:
            raise MavlinkError(f"timed out after {timeout_s:.1f} s waiting for {what}")
        now = ad.clock()
        if keepalive_hz > 0.0 and now >= next_keepalive:
            ad.send_velocity_enu(ZERO)
            next_keepalive = now + 1.0 / keepalive_hz
        wake = next_keepalive - now if keepalive_hz > 0.0 else 0.05
        ad.wait_readable(max(0.0, min(wake, 0.05)))


def wait_heard(ad: MavlinkAdapter, ok: Callable[[VehicleState], bool], timeout_s: float,
               what: str, t: StartupTimeouts, heard_what: str | None = None,
               keepalive_hz: float = 0.0) -> VehicleState:
    """`wait_until` counting only time the vehicle is heard (HeardClock), and failing once it
    is unheard for `t.silent_s`; `heard_what` names the wait in that error (default `what`)."""
    clock = HeardClock(ad, t.silent_s, heard_what or what)
    return wait_until(ad, ok, timeout_s, what, keepalive_hz, clock)


def command(ad: MavlinkAdapter, cmd: int, params: tuple[float, ...], t: StartupTimeouts,
            keepalive_hz: float = 0.0) -> None:
    """Send a command until ACCEPTED; raises CommandRejectedError or MavlinkError on timeout.

    No ACK, or TEMPORARILY_REJECTED: re-send every retry_s (of real time: a lost
    datagram is re-sent while unheard too).  IN_PROGRESS: keep waiting.  The timeout,
    command_s, counts only time the vehicle is heard (HeardClock).
    """
    heard = HeardClock(ad, t.silent_s, f"the ACK of command {cmd}")
    attempt = 0
    texts_before = ad.statustext_count
    while True:
        ad.send_command(cmd, params, confirmation=min(attempt, 255))
        attempt += 1
        retry_at = ad.clock() + t.retry_s

        def settled(_s: VehicleState, retry_at: float = retry_at) -> bool:
            result = ad.acks.get(cmd)
            if result in (ACCEPTED,) or result not in (None, TEMPORARILY_REJECTED, IN_PROGRESS):
                return True
            return heard() >= t.command_s or (result != IN_PROGRESS and ad.clock() >= retry_at)

        wait_until(ad, settled, t.command_s + 1.0, f"ACK of command {cmd}", keepalive_hz,
                   heard)
        result = ad.acks.get(cmd)
        if result == ACCEPTED:
            return
        if result not in (None, TEMPORARILY_REJECTED, IN_PROGRESS):
            raise CommandRejectedError(cmd, int(result), _why(ad, texts_before))
        if heard() >= t.command_s:
            if result is None:
                raise MavlinkError(f"no COMMAND_ACK for command {cmd} within {t.command_s:.1f} s")
            raise CommandRejectedError(cmd, result, "(still rejected at timeout) " +
                                       _why(ad, texts_before))


def _why(ad: MavlinkAdapter, texts_before: int) -> str:
    """The vehicle's STATUSTEXTs since the command was first sent: the reason for a refusal."""
    texts = ad.statustexts_since(texts_before)
    return f"({'; '.join(texts)})" if texts else ""


def set_mode(ad: MavlinkAdapter, name: str, t: StartupTimeouts, keepalive_hz: float = 0.0) -> None:
    if ad.flavour is None:
        raise MavlinkError("flavour unknown: no heartbeat yet")
    command(ad, MAV_CMD_DO_SET_MODE, do_set_mode_params(ad.flavour, name), t, keepalive_hz)
    wait_heard(ad, lambda s: s.mode == name, t.command_s, f"mode {name} in HEARTBEAT", t,
               f"mode {name}", keepalive_hz)


def _no_mark(phase: str) -> None:
    """The default `mark`: phases are not timed."""


def connect(ad: MavlinkAdapter, t: StartupTimeouts,
            mark: Callable[[str], None] = _no_mark) -> VehicleState:
    """Wait for the vehicle's heartbeat and its first position; ask for fast position telemetry."""
    wait_heartbeat(ad, t)
    mark("heartbeat")
    set_rates(ad, t)
    state = wait_position(ad, t)
    if ad.home_amsl_m is None:
        command(ad, MAV_CMD_REQUEST_MESSAGE, (MSG_HOME_POSITION,), t)
        state = wait_heard(ad, lambda _s: ad.home_amsl_m is not None, t.position_s,
                           "home altitude", t)
    mark("position")
    return state


def wait_position(ad: MavlinkAdapter, t: StartupTimeouts) -> VehicleState:
    """Wait for position telemetry (LOCAL_POSITION_NED: the link up) for `position_s` of
    heard time, as a command waits: a vehicle heard (HEARTBEATs) without a position for that
    long has none to give, one starved of CPU and sending nothing is unheard (64 followers
    on a slow 2-core machine all gave up here within their first 9 s of wall time)."""
    return wait_heard(ad, lambda s: s.link_ok, t.position_s, "LOCAL_POSITION_NED", t)


def stream_rates(t: StartupTimeouts) -> tuple[tuple[int, float], ...]:
    """(message id, Hz) an agent asks its vehicle for: LOCAL_POSITION_NED at the control's
    rate; ATTITUDE and GLOBAL_POSITION_INT (home altitude only) at `slow_telemetry_hz`."""
    return ((MSG_LOCAL_POSITION_NED, t.telemetry_hz), (MSG_ATTITUDE, t.slow_telemetry_hz),
            (MSG_GLOBAL_POSITION_INT, t.slow_telemetry_hz))


def set_rates(ad: MavlinkAdapter, t: StartupTimeouts) -> None:
    """Ask for `stream_rates`.  A refusal keeps the vehicle's default rate."""
    for msg_id, hz in stream_rates(t):
        try:
            command(ad, MAV_CMD_SET_MESSAGE_INTERVAL, (msg_id, 1e6 / hz), t)
        except MavlinkError as exc:  # the default rate still works, just coarser or dearer
            log.warning("vehicle %s kept its rate of message %d: %s", ad.sysid, msg_id, exc)


def wait_heartbeat(ad: MavlinkAdapter, t: StartupTimeouts) -> None:
    """Wait for the vehicle's first HEARTBEAT (its flavour and mode).

    Autopilots send it at 1 Hz: when the vehicle's address is known (PX4 SITL's ports),
    ask for one (REQUEST_MESSAGE, as PX4 and ArduPilot answer it) every
    `heartbeat_request_s` instead of waiting up to a second for the next (the vehicle may
    not listen yet when we start).  Unanswered requests cost nothing."""
    deadline = ad.clock() + t.heartbeat_s
    while ad.flavour is None:
        if ad.remote is not None and ad.sysid is not None:
            ad.send_command(MAV_CMD_REQUEST_MESSAGE, (MSG_HEARTBEAT,))
        left = deadline - ad.clock()
        if left <= 0.0:
            raise MavlinkError(f"timed out after {t.heartbeat_s:.1f} s waiting for vehicle "
                               "HEARTBEAT")
        try:
            wait_until(ad, lambda _s: ad.flavour is not None,
                       min(left, t.heartbeat_request_s), "vehicle HEARTBEAT")
        except MavlinkError:
            continue


def take_off(ad: MavlinkAdapter, altitude_m: float, t: StartupTimeouts,
             mark: Callable[[str], None] = _no_mark) -> VehicleState:
    """Arm and climb to altitude_m above home; skipped when already there.

    Streams zero-velocity setpoints while climbing: offboard then needs no further wait."""
    if ad.state.pos_enu_m[2] >= altitude_m - t.altitude_tolerance_m and ad.state.armed:
        return ad.state
    if ad.flavour == ARDUPILOT:
        set_mode(ad, "GUIDED", t)
        alt_param = altitude_m
    else:
        assert ad.home_amsl_m is not None
        alt_param = ad.home_amsl_m + altitude_m
    command(ad, MAV_CMD_COMPONENT_ARM_DISARM, (1.0,), t)
    mark("armed")
    command(ad, MAV_CMD_NAV_TAKEOFF, (0.0, 0.0, 0.0, math.nan, math.nan, math.nan, alt_param), t)
    mark("takeoff_accepted")
    state = wait_heard(ad, lambda s: s.pos_enu_m[2] >= altitude_m - t.altitude_tolerance_m,
                       t.takeoff_s, f"take-off to {altitude_m:.1f} m", t, "the take-off",
                       t.setpoint_hz)
    mark("at_altitude")
    return state


def start_offboard(ad: MavlinkAdapter, altitude_m: float, t: StartupTimeouts | None = None,
                   mark: Callable[[str], None] = _no_mark) -> VehicleState:
    """The whole start-up sequence; returns once the vehicle flies our velocity setpoints.

    `mark(phase)` is called as each phase ends (agents.shell.phases): heartbeat, position,
    armed, takeoff_accepted, at_altitude, offboard."""
    t = t or StartupTimeouts()
    connect(ad, t, mark)
    climb_from = ad.clock()
    take_off(ad, altitude_m, t, mark)
    assert ad.flavour is not None
    wanted = OFFBOARD_MODE[ad.flavour]
    # Setpoints must flow before offboard is asked for; the climb streamed them (if the
    # vehicle had to climb), and counts (most of it: the arm and take-off ACKs did not).
    deadline = max(ad.clock(), climb_from + t.stream_s)
    wait_until(ad, lambda _s: ad.clock() >= deadline, t.stream_s + 1.0, "setpoint stream",
               t.setpoint_hz)
    if ad.state.mode != wanted:
        set_mode(ad, wanted, t, t.setpoint_hz)
    mark("offboard")
    log.info("vehicle %s in %s at %.1f m", ad.sysid, wanted, ad.state.pos_enu_m[2])
    return ad.state
