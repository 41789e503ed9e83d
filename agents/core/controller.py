"""The enclosing controller (agents.law.enclosing) on numpy rows, for agents.follower_logic.

The law is agents.law.enclosing.enclosing_control's; this is its numpy form, kept while
agents.follower_logic's reference tick uses it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agents.core.geometry import as_complex, as_plane, limited_sig
from agents.law.enclosing import MIN_RANGE_M, TWO_PI, ControlGains, spacing_step_s
from agents.law.sig import rate_cap

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
    """agents.law.enclosing.enclosing_control of row-aligned (k, 2) positions, estimates
    and their rates, and (k,) desired included angles."""
    rel = as_complex(pos_m - r_m)
    rho = np.maximum(np.abs(rel), MIN_RANGE_M)
    radial = rel / rho
    z = rho - gains.rho_d_m
    turn = as_complex(succ_pos_m - r_m) * rel.conj()
    offset = np.mod(np.arctan2(turn.imag, turn.real) - angles_rad + np.pi, TWO_PI) - np.pi
    delta = offset / angles_rad
    cap = rate_cap(gains.step_fraction, dt_s)
    w_z = limited_sig(z, 1.0 / gains.alpha2, gains.k_z, cap)
    step_s = spacing_step_s(gains.step_fraction, gains.spacing_gain_age, dt_s, succ_age_s)
    delta_cap = (0.5 * rate_cap(gains.step_fraction, step_s)) * rho * angles_rad
    w_delta = limited_sig(delta, 1.0 / gains.alpha3, gains.k_d, delta_cap) + gains.w_d_rad_s * rho
    u = radial * (1j * w_delta - w_z) + as_complex(r_rate_m_s)
    return ControlOutput(u_m_s=as_plane(u), z_m=z, delta=delta)
