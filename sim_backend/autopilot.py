"""Mode logic of one simulated autopilot: arming, modes, take-off, land, offboard failsafe.

Pure: time and vehicle state are passed in, so tests drive it with a fake clock.
The result is a control row (what the airframe should do) for the vectorised model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from agents.mavlink.modes import (
    ARDUPILOT,
    HOLD_MODE,
    INITIAL_MODE,
    LAND_MODE,
    OFFBOARD_MODE,
    PX4,
    mode_of_do_set_mode,
)
from sim_backend.model import YAW_ANGLE, YAW_HOLD, YAW_RATE
from sim_backend.setpoint import Setpoint

MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
FORCE_MAGIC = 21196

ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED, FAILED = 0, 1, 2, 3, 4
TAKEOFF_REACHED_M = 0.2

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class ControlRow:
    """One vehicle's row of `model.FleetCommand`."""

    motors_on: bool
    pos_axis: tuple[bool, bool, bool]
    pos_sp_ned_m: Vec3
    vel_sp_ned_m_s: Vec3
    yaw_mode: int
    yaw_sp_rad: float
    yaw_rate_sp_rad_s: float


class Autopilot:
    """Flight-mode state machine; `dirty` tells the loop the control row changed."""

    def __init__(self, flavour: str, home_alt_m: float, takeoff_alt_m: float = 2.5,
                 setpoint_timeout_s: float = 0.5) -> None:
        self.flavour = flavour
        self.home_alt_m = home_alt_m
        self.default_takeoff_alt_m = takeoff_alt_m
        self.setpoint_timeout_s = setpoint_timeout_s
        self.armed = False
        self.mode = INITIAL_MODE[flavour]
        self.failsafes = 0
        self.dirty = True
        self._last_setpoint_s = -math.inf
        self._setpoint: Setpoint | None = None
        self._hold_ned_m: Vec3 = (0.0, 0.0, 0.0)
        self._takeoff_z_ned_m: float | None = None
        self._guided_velocity = False

    # ---- inputs -------------------------------------------------------------------------
    def setpoint_fresh(self, now_s: float) -> bool:
        return now_s - self._last_setpoint_s <= self.setpoint_timeout_s

    def on_setpoint(self, sp: Setpoint, now_s: float, landed: bool) -> None:
        self._last_setpoint_s = now_s
        self._setpoint = sp
        if self.mode == "GUIDED" and self.armed and not landed and self._takeoff_z_ned_m is None:
            self._guided_velocity = True
        if self.flying_setpoints():
            self.dirty = True

    def command(self, cmd: int, p: tuple[float, ...], now_s: float, pos: Vec3,
                landed: bool) -> int:
        """MAV_RESULT of one COMMAND_LONG/COMMAND_INT (params p[0..6])."""
        if cmd == MAV_CMD_COMPONENT_ARM_DISARM:
            return self._arm(p[0], p[1], now_s, pos, landed)
        if cmd == MAV_CMD_DO_SET_MODE:
            return self._set_mode_cmd(p, now_s, pos, landed)
        if cmd == MAV_CMD_NAV_TAKEOFF:
            return self._takeoff(p[6], pos)
        if cmd == MAV_CMD_NAV_LAND:
            self._enter(LAND_MODE[self.flavour], pos)
            return ACCEPTED
        return UNSUPPORTED

    def set_mode(self, name: str, now_s: float, pos: Vec3, landed: bool) -> int:
        if name == OFFBOARD_MODE[self.flavour]:
            on_ground = self.flavour == ARDUPILOT and (landed or not self.armed)
            if not (on_ground or self.setpoint_fresh(now_s)):
                return TEMPORARILY_REJECTED
        if name == "TAKEOFF" and self.armed:
            return self._takeoff(math.nan, pos)
        self._enter(name, pos)
        return ACCEPTED

    # ---- time ---------------------------------------------------------------------------
    def update(self, now_s: float, pos: Vec3, landed: bool) -> None:
        """Time- and state-driven transitions; call once per tick."""
        if not self.armed:
            return
        if self.flying_setpoints() and not self.setpoint_fresh(now_s):
            self.failsafes += 1
            self._enter(HOLD_MODE[self.flavour], pos)
        elif self._takeoff_z_ned_m is not None and \
                abs(pos[2] - self._takeoff_z_ned_m) < TAKEOFF_REACHED_M:
            target = (self._hold_ned_m[0], self._hold_ned_m[1], self._takeoff_z_ned_m)
            self._takeoff_z_ned_m = None
            self._enter("HOLD" if self.flavour == PX4 else self.mode, target)
        elif self.mode == LAND_MODE[self.flavour] and landed:
            self.armed = False
            self.dirty = True

    # ---- output -------------------------------------------------------------------------
    def flying_setpoints(self) -> bool:
        if not self.armed or self._setpoint is None:
            return False
        return self.mode == "OFFBOARD" or (self.mode == "GUIDED" and self._guided_velocity)

    def control(self) -> ControlRow:
        self.dirty = False
        hold = self._hold_ned_m
        if self.flying_setpoints() and self._setpoint is not None:
            return _setpoint_row(self._setpoint)
        if self._takeoff_z_ned_m is not None:
            return _pos_row(self.armed, (hold[0], hold[1], self._takeoff_z_ned_m))
        if self.mode == LAND_MODE[self.flavour]:
            return ControlRow(self.armed, (True, True, False), hold, (0.0, 0.0, 0.7),
                              YAW_HOLD, 0.0, 0.0)
        return _pos_row(self.armed, hold)

    # ---- helpers ------------------------------------------------------------------------
    def _enter(self, name: str, pos: Vec3) -> None:
        self.mode = name
        self._hold_ned_m = pos
        self._guided_velocity = False
        if name != "TAKEOFF" and name != "GUIDED":
            self._takeoff_z_ned_m = None
        self.dirty = True

    def _arm(self, p1: float, p2: float, now_s: float, pos: Vec3, landed: bool) -> int:
        if round(p1) == 1:
            if self.mode == "OFFBOARD" and not self.setpoint_fresh(now_s):
                return DENIED
            if not self.armed:
                self.armed = True
                self._enter(self.mode, pos)
                if self.mode == "TAKEOFF":
                    return self._takeoff(math.nan, pos)
            return ACCEPTED
        if self.armed and not landed and round(p2) != FORCE_MAGIC:
            return DENIED
        self.armed = False
        self._takeoff_z_ned_m = None
        self.dirty = True
        return ACCEPTED

    def _set_mode_cmd(self, p: tuple[float, ...], now_s: float, pos: Vec3, landed: bool) -> int:
        name = mode_of_do_set_mode(self.flavour, p[0], p[1], p[2])
        if name is None:
            return DENIED
        return self.set_mode(name, now_s, pos, landed)

    def _takeoff(self, alt_param_m: float, pos: Vec3) -> int:
        if not self.armed:
            return DENIED
        if self.flavour == ARDUPILOT:
            if self.mode != "GUIDED" or not math.isfinite(alt_param_m):
                return DENIED
            rel_alt_m = alt_param_m
        else:
            # PX4 reads param7 as AMSL; NaN means "use MIS_TAKEOFF_ALT".
            finite = math.isfinite(alt_param_m)
            rel_alt_m = alt_param_m - self.home_alt_m if finite else self.default_takeoff_alt_m
        if rel_alt_m <= 0.0:
            return DENIED
        self._enter("TAKEOFF" if self.flavour == PX4 else "GUIDED", pos)
        self._takeoff_z_ned_m = -rel_alt_m
        return ACCEPTED


def _pos_row(motors_on: bool, pos: Vec3) -> ControlRow:
    return ControlRow(motors_on, (True, True, True), pos, (0.0, 0.0, 0.0), YAW_HOLD, 0.0, 0.0)


def _setpoint_row(sp: Setpoint) -> ControlRow:
    if sp.yaw_rad is not None:
        yaw_mode, yaw, rate = YAW_ANGLE, sp.yaw_rad, 0.0
    elif sp.yaw_rate_rad_s is not None:
        yaw_mode, yaw, rate = YAW_RATE, 0.0, sp.yaw_rate_rad_s
    else:
        yaw_mode, yaw, rate = YAW_HOLD, 0.0, 0.0
    return ControlRow(True, sp.pos_axis, sp.pos_ned_m, sp.vel_ned_m_s, yaw_mode, yaw, rate)
