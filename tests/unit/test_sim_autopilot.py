"""Mode logic and offboard failsafe, driven by an injected time (no sleeps)."""

from __future__ import annotations

import math

from sim_backend.autopilot import (
    ACCEPTED,
    DENIED,
    TEMPORARILY_REJECTED,
    UNSUPPORTED,
    Autopilot,
)
from sim_backend.setpoint import decode_setpoint

GROUND = (0.0, 0.0, 0.0)
AIR = (1.0, 2.0, -10.0)
HOME_ALT = 488.0
ARM, MODE, TAKEOFF, LAND = 400, 176, 22, 21


def params(*p: float) -> tuple[float, ...]:
    return tuple(p) + (0.0,) * (7 - len(p))


def velocity(vx: float = 1.0):
    return decode_setpoint(3527, 1, (0.0,) * 3, (vx, 0.0, 0.0), 0.0, 0.0, AIR, 0.0)


def flying_px4() -> Autopilot:
    ap = Autopilot("px4", HOME_ALT)
    assert ap.command(ARM, params(1), 0.0, GROUND, True) == ACCEPTED
    assert ap.command(TAKEOFF, params(0, 0, 0, math.nan, math.nan, math.nan, HOME_ALT + 10),
                      0.0, GROUND, True) == ACCEPTED
    assert ap.mode == "TAKEOFF"
    ap.update(5.0, (0.0, 0.0, -9.9), False)
    assert ap.mode == "HOLD"
    return ap


def test_px4_takeoff_reads_amsl_altitude() -> None:
    ap = flying_px4()
    row = ap.control()
    assert row.pos_axis == (True, True, True) and row.pos_sp_ned_m[2] == -10.0


def test_offboard_refused_without_setpoints_then_accepted() -> None:
    ap = flying_px4()
    assert ap.command(MODE, params(1, 6, 0), 6.0, AIR, False) == TEMPORARILY_REJECTED
    assert ap.mode == "HOLD"
    ap.on_setpoint(velocity(), 6.0, False)
    assert ap.command(MODE, params(1, 6, 0), 6.2, AIR, False) == ACCEPTED
    assert ap.mode == "OFFBOARD"
    assert ap.control().vel_sp_ned_m_s == (1.0, 0.0, 0.0)


def test_offboard_failsafe_holds_after_half_a_second() -> None:
    ap = flying_px4()
    ap.on_setpoint(velocity(), 6.0, False)
    ap.command(MODE, params(1, 6, 0), 6.0, AIR, False)
    ap.update(6.45, AIR, False)
    assert ap.mode == "OFFBOARD"
    ap.update(6.55, AIR, False)
    assert ap.mode == "HOLD" and ap.failsafes == 1
    row = ap.control()
    assert row.pos_axis == (True, True, True) and row.pos_sp_ned_m == AIR


def test_disarm_in_air_denied_unless_forced() -> None:
    ap = flying_px4()
    assert ap.command(ARM, params(0), 6.0, AIR, False) == DENIED
    assert ap.command(ARM, params(0, 21196), 6.0, AIR, False) == ACCEPTED
    assert not ap.armed and not ap.control().motors_on


def test_land_disarms_on_touchdown() -> None:
    ap = flying_px4()
    assert ap.command(LAND, params(), 6.0, AIR, False) == ACCEPTED
    row = ap.control()
    assert row.pos_axis == (True, True, False) and row.vel_sp_ned_m_s[2] > 0
    ap.update(7.0, AIR, False)
    assert ap.armed
    ap.update(30.0, (1.0, 2.0, 0.0), True)
    assert ap.armed  # PX4 COM_DISARM_LAND: 2 s after touchdown
    ap.update(32.0, (1.0, 2.0, 0.0), True)
    assert not ap.armed


def test_takeoff_needs_arming_and_unknown_commands_unsupported() -> None:
    ap = Autopilot("px4", HOME_ALT)
    assert ap.command(TAKEOFF, params(0, 0, 0, 0, 0, 0, HOME_ALT + 5), 0.0, GROUND, True) == DENIED
    assert ap.command(12345, params(), 0.0, GROUND, True) == UNSUPPORTED
    assert ap.command(MODE, params(1, 42, 0), 0.0, GROUND, True) == DENIED


def test_px4_takeoff_nan_uses_default_altitude() -> None:
    ap = Autopilot("px4", HOME_ALT, takeoff_alt_m=2.5)
    ap.command(ARM, params(1), 0.0, GROUND, True)
    assert ap.command(TAKEOFF, params(0, 0, 0, 0, 0, 0, math.nan), 0.0, GROUND, True) == ACCEPTED
    assert ap.control().pos_sp_ned_m[2] == -2.5


def test_ardupilot_guided_takeoff_then_velocity_then_failsafe() -> None:
    ap = Autopilot("ardupilot", HOME_ALT)
    ap.command(ARM, params(1), 0.0, GROUND, True)
    assert ap.command(TAKEOFF, params(0, 0, 0, 0, 0, 0, 10.0), 0.0, GROUND, True) == DENIED
    assert ap.command(MODE, params(1, 4), 0.0, GROUND, True) == ACCEPTED  # GUIDED on the ground
    assert ap.command(TAKEOFF, params(0, 0, 0, 0, 0, 0, 10.0), 0.0, GROUND, True) == ACCEPTED
    ap.on_setpoint(velocity(), 1.0, False)  # ignored while taking off
    assert not ap.flying_setpoints()
    ap.update(5.0, (0.0, 0.0, -9.95), False)
    assert ap.mode == "GUIDED"
    ap.on_setpoint(velocity(), 5.1, False)
    assert ap.flying_setpoints() and ap.control().vel_sp_ned_m_s[0] == 1.0
    ap.update(5.7, AIR, False)
    # ArduPilot stays in GUIDED and stops (GUID_TIMEOUT), holding where it is.
    assert ap.mode == "GUIDED" and ap.failsafes == 1 and not ap.flying_setpoints()
    assert ap.control().pos_sp_ned_m == AIR and ap.notices
    ap.on_setpoint(velocity(), 6.0, False)  # a new setpoint resumes velocity control
    assert ap.flying_setpoints()


def test_ardupilot_guided_in_air_accepted_without_setpoints() -> None:
    ap = Autopilot("ardupilot", HOME_ALT)
    ap.command(MODE, params(1, 4), 0.0, GROUND, True)
    ap.command(ARM, params(1), 0.0, GROUND, True)
    ap.command(TAKEOFF, params(0, 0, 0, 0, 0, 0, 10.0), 0.0, GROUND, True)
    ap.update(5.0, (0.0, 0.0, -10.0), False)
    ap.set_mode("LOITER", 5.0, AIR, False)
    assert ap.set_mode("GUIDED", 9.0, AIR, False) == ACCEPTED
    assert not ap.flying_setpoints() and ap.control().pos_sp_ned_m == AIR  # holds
    ap.on_setpoint(velocity(), 9.1, False)
    assert ap.flying_setpoints()


def test_nan_and_bad_values_are_refused_with_a_reason_never_raised() -> None:
    ap = flying_px4()
    nan, inf = math.nan, math.inf
    for p1, p2, p3 in [(1, nan, 0), (1, 6, inf), (nan, 6, 0), (1, 4, 8), (1, 4, 9), (1, 1e30, 0)]:
        assert ap.command(MODE, params(p1, p2, p3), 6.0, AIR, False) == DENIED, (p1, p2, p3)
        assert ap.reason
    assert ap.mode == "HOLD"
    # NaN sub-mode means "unused": POSCTL (3) is selected.
    assert ap.command(MODE, params(1, 3, nan), 6.0, AIR, False) == ACCEPTED
    assert ap.set_mode("UNKNOWN(134479872)", 6.0, AIR, False) == DENIED  # AUTO.FOLLOW_TARGET
    assert ap.mode == "POSCTL"
    assert ap.command(ARM, params(nan), 6.0, AIR, False) == DENIED  # param1 is 0 or 1
    assert ap.command(ARM, params(0.5), 6.0, AIR, False) == DENIED
    assert ap.command(ARM, params(0, nan), 6.0, AIR, False) == DENIED  # NaN: not forced
    assert ap.armed


def test_arm_with_nan_in_unused_params_and_low_takeoff_raised() -> None:
    ap = Autopilot("px4", HOME_ALT, takeoff_alt_m=2.5)
    nan = math.nan
    assert ap.command(ARM, (1, nan, nan, nan, nan, nan, nan), 0.0, GROUND, True) == ACCEPTED
    assert ap.command(TAKEOFF, params(nan, 0, 0, nan, nan, nan, HOME_ALT + 1.0), 0.0, GROUND,
                      True) == ACCEPTED
    assert ap.control().pos_sp_ned_m[2] == -2.5  # raised to MIS_TAKEOFF_ALT
    assert "minimum takeoff altitude" in ap.notices[-1][1]


def test_rtl_climbs_returns_and_lands_then_disarms() -> None:
    ap = flying_px4()
    ap.rtl_alt_m = 12.0
    far = (30.0, -40.0, -10.0)
    assert ap.command(20, params(), 6.0, far, False) == ACCEPTED and ap.mode == "RTL"
    assert ap.control().pos_sp_ned_m == (30.0, -40.0, -12.0)  # climb first
    ap.update(8.0, (30.0, -40.0, -12.0), False)
    assert ap.control().pos_sp_ned_m == (0.0, 0.0, -12.0)  # then home
    ap.update(20.0, (0.1, 0.0, -12.0), False)
    row = ap.control()
    assert row.pos_axis == (True, True, False) and row.vel_sp_ned_m_s[2] > 0  # then land
    ap.update(30.0, (0.0, 0.0, 0.0), True)
    ap.update(32.5, (0.0, 0.0, 0.0), True)
    assert not ap.armed and ap.mode == "RTL"


def test_armed_idle_on_the_ground_disarms_after_preflight_delay() -> None:
    ap = Autopilot("px4", HOME_ALT)
    assert ap.command(ARM, params(1), 0.0, GROUND, True) == ACCEPTED
    ap.update(0.0, GROUND, True)
    ap.update(9.9, GROUND, True)
    assert ap.armed
    ap.update(10.0, GROUND, True)
    assert not ap.armed and "auto-disarm" in ap.notices[-1][1]
