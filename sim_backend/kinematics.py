"""Kinematic multirotor model: a pure, vectorised step over N vehicles in local NED.

Each axis is either position-controlled (a proportional loop gives the wanted
velocity) or velocity-controlled.  The wanted velocity is limited, then the
vehicle's velocity follows it with a first-order lag (time constant tau) whose
change per step is also acceleration-limited.  The ground is z_ned = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agents.scenario.model import VehicleConfig

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

YAW_HOLD, YAW_ANGLE, YAW_RATE = 0, 1, 2
GRAVITY_M_S2 = 9.80665
LANDED_EPS_M = 0.02


_VEHICLE = VehicleConfig()  # the limits' defaults are the scenario's, written there once


@dataclass(frozen=True)
class ModelParams:
    """Limits and loop constants of the kinematic model."""

    tau_s: float = _VEHICLE.tau_s
    max_speed_xy_m_s: float = _VEHICLE.max_speed_xy_m_s
    max_speed_z_m_s: float = _VEHICLE.max_speed_z_m_s
    max_accel_m_s2: float = _VEHICLE.max_accel_m_s2
    pos_gain_1_s: float = 2.0
    land_speed_m_s: float = 0.7
    tau_yaw_s: float = 0.2
    max_yaw_rate_rad_s: float = math.radians(120.0)

    @classmethod
    def from_vehicle(cls, cfg: VehicleConfig) -> ModelParams:
        return cls(tau_s=cfg.tau_s, max_speed_xy_m_s=cfg.max_speed_xy_m_s,
                   max_speed_z_m_s=cfg.max_speed_z_m_s, max_accel_m_s2=cfg.max_accel_m_s2)


@dataclass(frozen=True)
class FleetState:
    """State of N vehicles: (N, 3) NED arrays and (N,) yaw arrays."""

    pos_ned_m: FloatArray
    vel_ned_m_s: FloatArray
    acc_ned_m_s2: FloatArray
    yaw_rad: FloatArray
    yaw_rate_rad_s: FloatArray

    @classmethod
    def on_ground(cls, pos_ned_m: FloatArray) -> FleetState:
        pos = np.array(pos_ned_m, dtype=np.float64).reshape(-1, 3)
        pos[:, 2] = 0.0
        n = pos.shape[0]
        return cls(pos, np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n), np.zeros(n))

    @property
    def n(self) -> int:
        return int(self.pos_ned_m.shape[0])


@dataclass
class FleetCommand:
    """What each vehicle's autopilot asks of the airframe; mutable rows, one per vehicle."""

    motors_on: BoolArray
    pos_axis: BoolArray
    pos_sp_ned_m: FloatArray
    vel_sp_ned_m_s: FloatArray
    yaw_mode: NDArray[np.int8]
    yaw_sp_rad: FloatArray
    yaw_rate_sp_rad_s: FloatArray

    @classmethod
    def idle(cls, n: int) -> FleetCommand:
        return cls(np.zeros(n, bool), np.zeros((n, 3), bool), np.zeros((n, 3)), np.zeros((n, 3)),
                   np.zeros(n, np.int8), np.zeros(n), np.zeros(n))


def landed(state: FleetState) -> BoolArray:
    """On the ground and not climbing."""
    return (state.pos_ned_m[:, 2] >= -LANDED_EPS_M) & (state.vel_ned_m_s[:, 2] >= -0.05)


def _limit_xy(vec: FloatArray, limit: float) -> FloatArray:
    norm = np.hypot(vec[:, 0], vec[:, 1])
    scale = np.minimum(1.0, limit / np.maximum(norm, 1e-12))
    out = vec.copy()
    out[:, 0] *= scale
    out[:, 1] *= scale
    return out


def wanted_velocity(state: FleetState, cmd: FleetCommand, p: ModelParams) -> FloatArray:
    """Velocity each vehicle tries to reach, within its speed limits."""
    pos_loop = p.pos_gain_1_s * (cmd.pos_sp_ned_m - state.pos_ned_m)
    want = np.where(cmd.pos_axis, pos_loop, cmd.vel_sp_ned_m_s)
    # Motors off: nothing holds the vehicle up, so it sinks at the vertical limit.
    off = ~cmd.motors_on
    want[off, 0:2] = 0.0
    want[off, 2] = p.max_speed_z_m_s
    want = _limit_xy(want, p.max_speed_xy_m_s)
    want[:, 2] = np.clip(want[:, 2], -p.max_speed_z_m_s, p.max_speed_z_m_s)
    return want


def _yaw_rate(state: FleetState, cmd: FleetCommand, p: ModelParams) -> FloatArray:
    err = np.angle(np.exp(1j * (cmd.yaw_sp_rad - state.yaw_rad)))
    rate = np.where(cmd.yaw_mode == YAW_ANGLE, err / p.tau_yaw_s,
                    np.where(cmd.yaw_mode == YAW_RATE, cmd.yaw_rate_sp_rad_s, 0.0))
    return np.clip(rate, -p.max_yaw_rate_rad_s, p.max_yaw_rate_rad_s)


def pushed_by_air(vel_ned_m_s: FloatArray, air_ned_m_s: FloatArray, drag_1_s: float,
                  dt_s: float) -> FloatArray:
    """The velocity after the wind's force has pushed it for dt_s: the disturbance the
    velocity loop then rejects (agents.weather.gusts).  The force is linearised about
    hover, drag x wind: the frame's drag at its own speed is part of the loop's lag
    already, so still air pushes nothing."""
    return vel_ned_m_s + air_ned_m_s * (1.0 - math.exp(-dt_s * drag_1_s))


def step(state: FleetState, cmd: FleetCommand, p: ModelParams, dt_s: float,
         air_ned_m_s: FloatArray | None = None, drag_1_s: float = 0.0) -> FleetState:
    """Advance every vehicle by dt_s; inputs are not modified.  `air_ned_m_s`: the wind
    each vehicle is in (None: still air, and not a single operation more)."""
    want = wanted_velocity(state, cmd, p)
    vel0 = state.vel_ned_m_s
    if air_ned_m_s is not None:
        vel0 = pushed_by_air(vel0, air_ned_m_s, drag_1_s, dt_s)
    # Exact discretisation of the first-order lag: stable for any dt, not only dt << tau.
    dv = (want - vel0) * (1.0 - math.exp(-dt_s / p.tau_s))
    max_dv = p.max_accel_m_s2 * dt_s
    dv = _limit_xy(dv, max_dv)
    dv[:, 2] = np.clip(dv[:, 2], -max_dv, max_dv)
    vel = vel0 + dv
    # A multirotor on the ground does not slide: only a climb command frees it (PX4 lifts
    # off in offboard only with vz < 0).  Decided before integrating, so it cannot creep.
    stuck = (state.pos_ned_m[:, 2] >= 0.0) & (want[:, 2] >= 0.0)
    vel[stuck] = 0.0
    vel_before = state.vel_ned_m_s.copy()
    vel_before[stuck] = 0.0
    pos = state.pos_ned_m + 0.5 * (vel_before + vel) * dt_s
    ground = pos[:, 2] >= 0.0
    pos[ground, 2] = 0.0
    vel[ground, 2] = np.minimum(vel[ground, 2], 0.0)
    yaw_rate = np.where(stuck, 0.0, _yaw_rate(state, cmd, p))
    yaw = np.angle(np.exp(1j * (state.yaw_rad + yaw_rate * dt_s)))
    acc = (vel - state.vel_ned_m_s) / dt_s
    return FleetState(pos, vel, acc, yaw, yaw_rate)


def tilt_rad(acc_ned_m_s2: FloatArray, yaw_rad: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Roll and pitch a multirotor needs for a horizontal acceleration (hover thrust = g)."""
    a_fwd = acc_ned_m_s2[:, 0] * np.cos(yaw_rad) + acc_ned_m_s2[:, 1] * np.sin(yaw_rad)
    a_right = -acc_ned_m_s2[:, 0] * np.sin(yaw_rad) + acc_ned_m_s2[:, 1] * np.cos(yaw_rad)
    return np.arctan2(a_right, GRAVITY_M_S2), np.arctan2(-a_fwd, GRAVITY_M_S2)
