"""The paper's finite-time enclosing controller (eq. finite-time-controller-single), pure.

    u_i = phi_i * (-k_z sig(z_i)^(1/alpha2))
        + phi_perp_i * (k_d sig(delta_i)^(1/alpha3) + w_d * rho'_i) + dr_i/dt

w_d is read as an angular rate (NOTES.md), hence the tangential speed w_d * rho'.
Both fractional-power terms are step-limited (geometry.limited_sig) so that a
sampled loop does not dither; with step_fraction = 0 this is the paper's law.
Works row-wise, so one follower (rows of 1) and a whole swarm (rows of n) share it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agents.core.geometry import TWO_PI, limited_sig, limited_sig_one, rate_cap

FloatArray = NDArray[np.float64]
MIN_RANGE_M = 1e-9


@dataclass(frozen=True)
class ControlGains:
    k_z: float
    alpha2: float
    k_d: float
    alpha3: float
    rho_d_m: float
    w_d_rad_s: float
    step_fraction: float = 0.5  # see geometry.limited_sig; 0 gives the plain law


@dataclass(frozen=True)
class ControlOutput:
    u_m_s: FloatArray  # (k, 2) velocity command
    z_m: FloatArray  # (k,) estimated radius error rho' - rho_d
    delta: FloatArray  # (k,) estimated included-angle error gap/a - 1


def enclosing_control(
    pos_m: FloatArray,
    succ_pos_m: FloatArray,
    r_m: FloatArray,
    r_rate_m_s: FloatArray,
    angles_rad: FloatArray,
    gains: ControlGains,
    dt_s: float,
    succ_age_s: float = 0.0,
) -> ControlOutput:
    """Velocity commands for followers at `pos_m` whose successors are at `succ_pos_m`.

    All arrays are row-aligned: (k, 2) positions, estimates r and their rates, (k,)
    desired included angles a_i.  `dt_s` is the time until the next command: it
    sets how much of the error one command may remove (`ControlGains.step_fraction`);
    `succ_age_s`, the age of the successor's position, stretches that step for the
    angle: correcting on data older than a step by a step's worth oscillates.
    """
    # Plane vectors as complex numbers (zero-copy views): one call each for the
    # norm, the relative bearing and the 90-degree rotation keeps a 1 kHz loop cheap.
    rel = as_complex(pos_m - r_m)
    rho = np.maximum(np.abs(rel), MIN_RANGE_M)
    radial = rel / rho
    z = rho - gains.rho_d_m
    # Bearing of the successor relative to our own, both seen from r_i.
    turn = as_complex(succ_pos_m - r_m) * rel.conj()
    delta = np.mod(np.arctan2(turn.imag, turn.real), TWO_PI) / angles_rad - 1.0
    cap = rate_cap(gains.step_fraction, dt_s)
    w_z = limited_sig(z, 1.0 / gains.alpha2, gains.k_z, cap)
    # Half the cap for the angle: the successor's own correction moves delta_i too.
    delta_cap = (0.5 * rate_cap(gains.step_fraction, max(dt_s, succ_age_s))) * rho * angles_rad
    w_delta = limited_sig(delta, 1.0 / gains.alpha3, gains.k_d, delta_cap) + gains.w_d_rad_s * rho
    u = radial * (1j * w_delta - w_z) + as_complex(r_rate_m_s)
    return ControlOutput(u_m_s=as_plane(u), z_m=z, delta=delta)


def enclosing_control_one(
    pos_m: complex,
    succ_pos_m: complex,
    r_m: complex,
    r_rate_m_s: complex,
    angle_rad: float,
    gains: ControlGains,
    dt_s: float,
    succ_age_s: float = 0.0,
) -> tuple[complex, float, float]:
    """`enclosing_control` for one follower, plane vectors as complex x + iy: (u, z, delta).

    The same law line by line, on Python floats: numpy's per-call cost is most of a
    one-row call's (the networked follower computes one row per tick)."""
    rel = pos_m - r_m
    rho = max(abs(rel), MIN_RANGE_M)
    radial = rel / rho
    z = rho - gains.rho_d_m
    turn = (succ_pos_m - r_m) * rel.conjugate()
    delta = math.atan2(turn.imag, turn.real) % TWO_PI / angle_rad - 1.0
    cap = rate_cap(gains.step_fraction, dt_s)
    w_z = limited_sig_one(z, 1.0 / gains.alpha2, gains.k_z, cap)
    delta_cap = (0.5 * rate_cap(gains.step_fraction, max(dt_s, succ_age_s))) * rho * angle_rad
    w_delta = (limited_sig_one(delta, 1.0 / gains.alpha3, gains.k_d, delta_cap)
               + gains.w_d_rad_s * rho)
    return radial * (1j * w_delta - w_z) + r_rate_m_s, z, delta


def as_complex(vec_m: FloatArray) -> NDArray[np.complex128]:
    """(k, 2) float rows as (k,) complex x + iy, without copying when contiguous."""
    if not (vec_m.flags.c_contiguous and vec_m.dtype == np.float64):
        vec_m = np.ascontiguousarray(vec_m, dtype=np.float64)
    return vec_m.view(np.complex128)[:, 0]


def as_plane(vec: NDArray[np.complex128]) -> FloatArray:
    """(k,) complex back to (k, 2) float rows, without copying."""
    return vec.view(np.float64).reshape(-1, 2)
