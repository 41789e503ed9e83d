"""The paper's finite-time enclosing controller (eq. finite-time-controller-single), pure.

    u_i = phi_i * (-k_z sig(z_i)^(1/alpha2))
        + phi_perp_i * (k_d sig(delta_i)^(1/alpha3) + w_d * rho'_i) + dr_i/dt

w_d is read as an angular rate (NOTES.md), hence the tangential speed w_d * rho'.
Both fractional-power terms are step-limited (geometry.limited_sig) so that a
sampled loop does not dither; with step_fraction = 0 this is the paper's law.
Works row-wise, so one follower (rows of 1) and a whole swarm (rows of n) share it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

# The gains and the one-follower twin live without numpy, for the follower process.
from agents.core.controller_one import MIN_RANGE_M as MIN_RANGE_M
from agents.core.controller_one import ControlGains as ControlGains
from agents.core.controller_one import enclosing_control_one as enclosing_control_one
from agents.core.controller_one import spacing_step_s
from agents.core.geometry import TWO_PI, limited_sig, rate_cap

FloatArray = NDArray[np.float64]


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
    angle: correcting on data older than a step by a step's worth oscillates
    (controller_one.spacing_step_s).
    """
    # Plane vectors as complex numbers (zero-copy views): one call each for the
    # norm, the relative bearing and the 90-degree rotation keeps a 1 kHz loop cheap.
    rel = as_complex(pos_m - r_m)
    rho = np.maximum(np.abs(rel), MIN_RANGE_M)
    radial = rel / rho
    z = rho - gains.rho_d_m
    # Bearing of the successor relative to our own, both seen from r_i.
    turn = as_complex(succ_pos_m - r_m) * rel.conj()
    # The gap wraps to within half a turn of a_i (controller_one says why).
    offset = np.mod(np.arctan2(turn.imag, turn.real) - angles_rad + np.pi, TWO_PI) - np.pi
    delta = offset / angles_rad
    cap = rate_cap(gains.step_fraction, dt_s)
    w_z = limited_sig(z, 1.0 / gains.alpha2, gains.k_z, cap)
    # Half the cap for the angle: the successor's own correction moves delta_i too.
    step_s = spacing_step_s(gains, dt_s, succ_age_s)
    delta_cap = (0.5 * rate_cap(gains.step_fraction, step_s)) * rho * angles_rad
    w_delta = limited_sig(delta, 1.0 / gains.alpha3, gains.k_d, delta_cap) + gains.w_d_rad_s * rho
    u = radial * (1j * w_delta - w_z) + as_complex(r_rate_m_s)
    return ControlOutput(u_m_s=as_plane(u), z_m=z, delta=delta)


def as_complex(vec_m: FloatArray) -> NDArray[np.complex128]:
    """(k, 2) float rows as (k,) complex x + iy, without copying when contiguous."""
    if not (vec_m.flags.c_contiguous and vec_m.dtype == np.float64):
        vec_m = np.ascontiguousarray(vec_m, dtype=np.float64)
    return vec_m.view(np.complex128)[:, 0]


def as_plane(vec: NDArray[np.complex128]) -> FloatArray:
    """(k,) complex back to (k, 2) float rows, without copying."""
    return vec.view(np.float64).reshape(-1, 2)
