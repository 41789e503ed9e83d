"""Kinematic model: limits, time constant, ground contact, take-off, land."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_backend import kinematics
from sim_backend.kinematics import FleetCommand, FleetState, ModelParams

DT = 0.01


def run(state: FleetState, cmd: FleetCommand, p: ModelParams, seconds: float) -> FleetState:
    for _ in range(round(seconds / DT)):
        state = kinematics.step(state, cmd, p, DT)
    return state


def hovering(n: int = 1, alt_m: float = 10.0) -> FleetState:
    s = FleetState.on_ground(np.zeros((n, 3)))
    s.pos_ned_m[:, 2] = -alt_m
    return s


def velocity_cmd(n: int, vel_ned: tuple[float, float, float]) -> FleetCommand:
    c = FleetCommand.idle(n)
    c.motors_on[:] = True
    c.vel_sp_ned_m_s[:] = vel_ned
    return c


def test_speed_limits_horizontal_and_vertical() -> None:
    p = ModelParams(max_speed_xy_m_s=5.0, max_speed_z_m_s=2.0)
    s = run(hovering(), velocity_cmd(1, (30.0, 40.0, -10.0)), p, 2.0)
    assert math.hypot(*s.vel_ned_m_s[0, :2]) == pytest.approx(5.0, abs=1e-6)
    assert s.vel_ned_m_s[0, 2] == pytest.approx(-2.0, abs=1e-6)
    # direction of the horizontal command is kept when limiting
    assert s.vel_ned_m_s[0, 1] / s.vel_ned_m_s[0, 0] == pytest.approx(40.0 / 30.0)


def test_first_order_time_constant() -> None:
    p = ModelParams(tau_s=0.5, max_accel_m_s2=1000.0)
    s = run(hovering(), velocity_cmd(1, (1.0, 0.0, 0.0)), p, 0.5)
    assert s.vel_ned_m_s[0, 0] == pytest.approx(1.0 - math.exp(-1.0), abs=1e-6)


def test_acceleration_limit() -> None:
    p = ModelParams(tau_s=0.01, max_accel_m_s2=2.0)
    s = run(hovering(), velocity_cmd(1, (10.0, 0.0, 0.0)), p, 1.0)
    assert s.vel_ned_m_s[0, 0] == pytest.approx(2.0, abs=1e-6)


def test_ground_contact_stops_descent_and_sliding() -> None:
    p = ModelParams()
    s = run(hovering(alt_m=1.0), velocity_cmd(1, (2.0, 0.0, 3.0)), p, 3.0)
    assert s.pos_ned_m[0, 2] == 0.0
    assert np.all(s.vel_ned_m_s[0] == 0.0)
    assert bool(kinematics.landed(s)[0])


def test_motors_off_on_ground_stays_put_and_in_air_falls() -> None:
    p = ModelParams()
    ground = run(FleetState.on_ground(np.zeros((1, 3))), FleetCommand.idle(1), p, 1.0)
    assert ground.pos_ned_m[0, 2] == 0.0
    air = run(hovering(alt_m=2.0), FleetCommand.idle(1), p, 3.0)
    assert air.pos_ned_m[0, 2] == 0.0


def test_takeoff_and_land_with_position_axes() -> None:
    p = ModelParams()
    cmd = FleetCommand.idle(2)
    cmd.motors_on[:] = True
    cmd.pos_axis[:] = True
    cmd.pos_sp_ned_m[:] = (0.0, 0.0, -5.0)
    s = run(FleetState.on_ground(np.zeros((2, 3))), cmd, p, 6.0)
    assert s.pos_ned_m[:, 2] == pytest.approx([-5.0, -5.0], abs=0.05)
    assert not kinematics.landed(s).any()
    cmd.pos_axis[:] = (True, True, False)
    cmd.vel_sp_ned_m_s[:] = (0.0, 0.0, p.land_speed_m_s)
    s = run(s, cmd, p, 5.0 / p.land_speed_m_s + 1.0)
    assert kinematics.landed(s).all()


def test_vectorised_rows_are_independent() -> None:
    p = ModelParams()
    cmd = velocity_cmd(3, (0.0, 0.0, 0.0))
    cmd.vel_sp_ned_m_s[1] = (1.0, 0.0, 0.0)
    s = run(hovering(3), cmd, p, 1.0)
    assert s.pos_ned_m[1, 0] > 0.5
    assert s.pos_ned_m[0, 0] == 0.0 and s.pos_ned_m[2, 0] == 0.0


def test_yaw_tracks_angle_and_rate() -> None:
    p = ModelParams()
    cmd = velocity_cmd(2, (0.0, 0.0, 0.0))
    cmd.yaw_mode[:] = (kinematics.YAW_ANGLE, kinematics.YAW_RATE)
    cmd.yaw_sp_rad[0] = 1.0
    cmd.yaw_rate_sp_rad_s[1] = 0.5
    s = run(hovering(2), cmd, p, 2.0)
    assert s.yaw_rad[0] == pytest.approx(1.0, abs=1e-3)
    assert s.yaw_rad[1] == pytest.approx(1.0, abs=0.02)
