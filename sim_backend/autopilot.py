"""Mode logic of one simulated autopilot: arming, modes, take-off, land, RTL, failsafes.

Pure: time and vehicle state are passed in, so tests drive it with a fake clock.
The result is a control row (what the airframe should do) for the vectorised model.
Every refusal leaves its reason in `reason`; things a pilot must hear (failsafes,
auto-disarm, a raised take-off altitude) queue in `notices` as STATUSTEXT would.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from agents.mavlink.modes import (
    ARDUPILOT,
    HOLD_MODE,
    INITIAL_MODE,
    LAND_MODE,
    PX4,
    known_mode,
    mode_of_do_set_mode,
)
from sim_backend.kinematics import YAW_ANGLE, YAW_HOLD, YAW_RATE
from sim_backend.setpoint import Setpoint

MAV_CMD_NAV_RETURN_TO_LAUNCH = 20
MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
FORCE_MAGIC = 21196

ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED, FAILED = 0, 1, 2, 3, 4
SEVERITY_CRITICAL, SEVERITY_WARNING, SEVERITY_INFO = 2, 4, 6
TAKEOFF_REACHED_M = 0.2
RTL_REACHED_M = 0.3
# Modes in the flavour's table whose behaviour the simulator does not model (missions).
UNMODELLED = {PX4: ("MISSION",), ARDUPILOT: ("AUTO",)}

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
                 setpoint_timeout_s: float = 0.5, home_ned_m: Vec3 = (0.0, 0.0, 0.0)) -> None:
        self.flavour = flavour
        self.home_alt_m = home_alt_m
        self.home_ned_m = home_ned_m
        self.default_takeoff_alt_m = takeoff_alt_m
        self.setpoint_timeout_s = setpoint_timeout_s
        self.rtl_alt_m = 10.0
        self.disarm_preflight_s = 10.0  # PX4 COM_DISARM_PRFLT, ArduPilot DISARM_DELAY
        self.disarm_land_s = 2.0  # PX4 COM_DISARM_LAND
        self.armed = False
        self.mode = INITIAL_MODE[flavour]
        self.failsafes = 0
        self.dirty = True
        self.reason = ""
        self.notices: list[tuple[int, str]] = []
        self._last_setpoint_s = -math.inf
        self._setpoint: Setpoint | None = None
        self._hold_ned_m: Vec3 = (0.0, 0.0, 0.0)
        self._takeoff_z_ned_m: float | None = None
        self._guided_velocity = False
        self._rtl_phase = ""
        self._ground_since_s: float | None = None
        self._airborne = False

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
        """MAV_RESULT of one COMMAND_LONG/COMMAND_INT (params p[0..6], NaN = unused)."""
        if cmd == MAV_CMD_COMPONENT_ARM_DISARM:
            return self._arm(p[0], p[1], now_s, pos, landed)
        if cmd == MAV_CMD_DO_SET_MODE:
            name = mode_of_do_set_mode(self.flavour, p[0], p[1], p[2])
            if name is None:
                return self._refuse(DENIED, f"DO_SET_MODE {p[0]:g}/{p[1]:g}/{p[2]:g}: "
                                            "no such mode")
            return self.set_mode(name, now_s, pos, landed)
        if cmd == MAV_CMD_NAV_TAKEOFF:
            return self._takeoff(p[6], pos)
        if cmd == MAV_CMD_NAV_LAND:
            return self.set_mode(LAND_MODE[self.flavour], now_s, pos, landed)
        if cmd == MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self.set_mode("RTL", now_s, pos, landed)
        return self._refuse(UNSUPPORTED, f"command {cmd} not supported")

    def set_mode(self, name: str, now_s: float, pos: Vec3, landed: bool) -> int:
        if not known_mode(self.flavour, name):
            return self._refuse(DENIED, f"mode {name} not supported by this autopilot")
        if name in UNMODELLED[self.flavour]:
            return self._refuse(DENIED, f"mode {name} not simulated (missions are not flown)")
        if name == "OFFBOARD" and not self.setpoint_fresh(now_s):
            return self._refuse(TEMPORARILY_REJECTED, "Offboard refused: no setpoint in the "
                                f"last {self.setpoint_timeout_s:g} s")
        if name == "TAKEOFF" and self.armed:
            return self._takeoff(math.nan, pos)
        self._enter(name, pos)
        if name == "RTL":
            # Climb to the return altitude, fly home, land there; on the ground: land at once.
            z = min(pos[2], self.home_ned_m[2] - self.rtl_alt_m)
            self._rtl_phase = "land" if landed else "climb"
            self._hold_ned_m = (pos[0], pos[1], z)
        # ArduPilot GUIDED in the air flies fresh setpoints at once, else holds position.
        if name == "GUIDED" and self.armed and not landed and self.setpoint_fresh(now_s):
            self._guided_velocity = True
        return ACCEPTED

    def reposition(self, target_ned_m: Vec3, landed: bool) -> int:
        """MAV_CMD_DO_REPOSITION: fly to a point and hold there (PX4 HOLD, ArduPilot GUIDED)."""
        if not self.armed or landed:
            return self._refuse(DENIED, "reposition refused: vehicle is not flying")
        name = "HOLD" if self.flavour == PX4 else "GUIDED"
        self._enter(name, target_ned_m)
        return ACCEPTED

    # ---- time ---------------------------------------------------------------------------
    def update(self, now_s: float, pos: Vec3, landed: bool) -> None:
        """Time- and state-driven transitions; call once per tick."""
        if not self.armed:
            return
        if self.flying_setpoints() and not self.setpoint_fresh(now_s):
            self._setpoint_lost(pos)
        elif self._takeoff_z_ned_m is not None and \
                abs(pos[2] - self._takeoff_z_ned_m) < TAKEOFF_REACHED_M:
            target = (self._hold_ned_m[0], self._hold_ned_m[1], self._takeoff_z_ned_m)
            self._takeoff_z_ned_m = None
            self._enter("HOLD" if self.flavour == PX4 else self.mode, target)
        elif self.mode == "RTL":
            self._rtl_step(pos, landed)
        self._auto_disarm(now_s, landed)

    def _setpoint_lost(self, pos: Vec3) -> None:
        self.failsafes += 1
        if self.flavour == PX4:
            # The documented choice: hold after 0.5 s (PX4's COM_OF_LOSS_T default is 1 s).
            self._enter(HOLD_MODE[PX4], pos)
            self.notices.append((SEVERITY_CRITICAL, "Failsafe: offboard setpoints lost, "
                                                    "holding position"))
        else:
            # ArduPilot stays in GUIDED and stops after GUID_TIMEOUT.
            self._enter(self.mode, pos)
            self.notices.append((SEVERITY_WARNING, "Guided: setpoints timed out, stopping"))

    def _rtl_step(self, pos: Vec3, landed: bool) -> None:
        target = self._hold_ned_m
        if self._rtl_phase == "climb" and abs(pos[2] - target[2]) < TAKEOFF_REACHED_M:
            self._rtl_phase = "return"
            self._hold_ned_m = (self.home_ned_m[0], self.home_ned_m[1], target[2])
            self.dirty = True
        elif self._rtl_phase == "return" and \
                math.hypot(pos[0] - target[0], pos[1] - target[1]) < RTL_REACHED_M:
            self._rtl_phase = "land"
            self.dirty = True

    def _auto_disarm(self, now_s: float, landed: bool) -> None:
        """Disarm after COM_DISARM_PRFLT on the ground before flight, COM_DISARM_LAND after."""
        if not landed or self._takeoff_z_ned_m is not None:
            self._ground_since_s = None
            self._airborne = self._airborne or not landed
            return
        if self._ground_since_s is None:
            self._ground_since_s = now_s
        limit = self.disarm_land_s if self._airborne else self.disarm_preflight_s
        if now_s - self._ground_since_s >= limit:
            self._disarm()
            self.notices.append((SEVERITY_INFO, "Disarmed by auto-disarm on the ground"))

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
        landing = self.mode == LAND_MODE[self.flavour] or self._rtl_phase == "land"
        if landing:
            return ControlRow(self.armed, (True, True, False), (hold[0], hold[1], 0.0),
                              (0.0, 0.0, 0.7), YAW_HOLD, 0.0, 0.0)
        return _pos_row(self.armed, hold)

    # ---- helpers ------------------------------------------------------------------------
    def _refuse(self, result: int, why: str) -> int:
        self.reason = why
        return result

    def _enter(self, name: str, pos: Vec3) -> None:
        self.mode = name
        self._hold_ned_m = pos
        self._guided_velocity = False
        self._rtl_phase = ""
        if name != "TAKEOFF" and name != "GUIDED":
            self._takeoff_z_ned_m = None
        self.dirty = True

    def _disarm(self) -> None:
        self.armed = False
        self._takeoff_z_ned_m = None
        self._rtl_phase = ""
        self._ground_since_s = None
        self.dirty = True

    def _arm(self, p1: float, p2: float, now_s: float, pos: Vec3, landed: bool) -> int:
        # param1 is a MAV_BOOL (exactly 0 or 1); param2 21196 forces, anything else (NaN) not.
        if p1 == 1.0:
            if self.mode == "OFFBOARD" and not self.setpoint_fresh(now_s):
                return self._refuse(DENIED, "Arming denied: offboard without setpoints")
            if not self.armed:
                self.armed = True
                self._airborne = not landed
                if landed:
                    self.home_ned_m = pos
                self._enter(self.mode, pos)
                if self.mode == "TAKEOFF":
                    return self._takeoff(math.nan, pos)
            return ACCEPTED
        if p1 != 0.0:
            return self._refuse(DENIED, f"ARM_DISARM param1 must be 0 or 1, not {p1:g}")
        if self.armed and not landed and p2 != FORCE_MAGIC:
            return self._refuse(DENIED, "Disarming denied: vehicle is flying (force: 21196)")
        self._disarm()
        return ACCEPTED

    def _takeoff(self, alt_param_m: float, pos: Vec3) -> int:
        if not self.armed:
            return self._refuse(DENIED, "Takeoff denied: vehicle not armed")
        if self.flavour == ARDUPILOT:
            if self.mode != "GUIDED":
                return self._refuse(DENIED, "Takeoff denied: not in GUIDED")
            if not math.isfinite(alt_param_m) or alt_param_m <= 0.0:
                return self._refuse(DENIED, "Takeoff denied: altitude must be above 0 m")
            rel_alt_m = alt_param_m
        else:
            rel_alt_m = self._px4_takeoff_alt(alt_param_m)
        self._enter("TAKEOFF" if self.flavour == PX4 else "GUIDED", pos)
        self._takeoff_z_ned_m = self.home_ned_m[2] - rel_alt_m
        return ACCEPTED

    def _px4_takeoff_alt(self, alt_param_m: float) -> float:
        """PX4 reads param7 as AMSL; NaN means MIS_TAKEOFF_ALT, which is also the minimum."""
        minimum = self.default_takeoff_alt_m
        if not math.isfinite(alt_param_m):
            return minimum
        rel_alt_m = alt_param_m - self.home_alt_m
        if rel_alt_m < minimum - 0.1:
            self.notices.append((SEVERITY_WARNING,
                                 f"Using minimum takeoff altitude: {minimum:.2f} m"))
        return max(rel_alt_m, minimum)


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
