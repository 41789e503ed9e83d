"""The paper's finite-time enclosing controller (eq. finite-time-controller-single), one follower.

    u_i = phi_i * (-k_z sig(z_i)^(1/alpha2))
        + phi_perp_i * (k_d sig(delta_i)^(1/alpha3) + w_d * rho'_i) + dr_i/dt

with rho'_i = |p_i - r_i|, phi_i = (p_i - r_i) / rho'_i, z_i = rho'_i - rho_d and
delta_i = gap_i / a_i - 1.  w_d is read as an angular rate (paper/NOTES.md), hence the
tangential speed w_d * rho'_i.  Both fractional-power terms are step-limited
(agents.law.sig.limited_sig) so that a sampled loop does not dither; with
step_fraction = 0 this is the paper's law.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from agents.law.sig import limited_sig, rate_cap

TWO_PI = 2.0 * math.pi
MIN_RANGE_M = 1e-9


@dataclass(frozen=True)
class ControlGains:
    k_z: float
    alpha2: float
    k_d: float
    alpha3: float
    rho_d_m: float
    w_d_rad_s: float
    step_fraction: float = 0.5  # see agents.law.sig.limited_sig; 0 gives the plain law
    # Largest product of the spacing law's linear gain and its successor's data age
    # (Gains.spacing_gain_age); 0: step_fraction / 2, one step's share per age.
    spacing_gain_age: float = 0.0


def spacing_step_s(step_fraction: float, spacing_gain_age: float, dt_s: float,
                   succ_age_s: float) -> float:
    """The step the angle's cap is computed for: dt, stretched by the successor's data age.

    Near zero the spacing law is linear with gain g = step_fraction / (2 dt) (half the cap:
    the successor's own correction moves delta too).  Correcting on data of age L with
    g L large oscillates, so the gain is cut to spacing_gain_age / L where g L would
    exceed it; by default (0) that is at any age beyond a period."""
    if spacing_gain_age <= 0.0 or step_fraction <= 0.0:
        return max(dt_s, succ_age_s)
    return max(dt_s, succ_age_s * 0.5 * step_fraction / spacing_gain_age)


def enclosing_control(
    pos_m: complex,
    succ_pos_m: complex,
    r_m: complex,
    r_rate_m_s: complex,
    angle_rad: float,
    k_z: float,
    inv_alpha2: float,
    k_d: float,
    inv_alpha3: float,
    rho_d_m: float,
    w_d_rad_s: float,
    step_fraction: float,
    spacing_gain_age: float,
    dt_s: float,
    succ_age_s: float,
) -> tuple[complex, float, float]:
    """(u, z, delta) of a follower at `pos_m` whose successor is at `succ_pos_m`.

    `r_m`, `r_rate_m_s`: its estimate of the LAP and the estimate's rate; `angle_rad`:
    its desired included angle a_i; then `ControlGains` as plain floats (the exponents
    1/alpha).  `dt_s` is the time until the next command: it sets how much of the error
    one command may remove; `succ_age_s`, the age of the successor's position, stretches
    that step for the angle (`spacing_step_s`).
    """
    rel = pos_m - r_m
    rho = max(abs(rel), MIN_RANGE_M)
    radial = rel / rho
    z = rho - rho_d_m
    # The successor's bearing relative to our own, both seen from r_i.
    turn = (succ_pos_m - r_m) * rel.conjugate()
    # The gap wraps to within half a turn of the desired angle, not to [0, 2 pi): a
    # successor fallen just behind (the order inverted: a vehicle held still while the
    # ring turned) reads as a negative gap and is waited for, instead of chased round
    # the whole ring into a wound formation.  Orders that never invert see the paper's.
    delta = ((math.atan2(turn.imag, turn.real) - angle_rad + math.pi) % TWO_PI - math.pi) \
        / angle_rad
    w_z = limited_sig(z, inv_alpha2, k_z, rate_cap(step_fraction, dt_s))
    # Half the cap for the angle: the successor's own correction moves delta_i too.
    step_s = spacing_step_s(step_fraction, spacing_gain_age, dt_s, succ_age_s)
    delta_cap = (0.5 * rate_cap(step_fraction, step_s)) * rho * angle_rad
    w_delta = limited_sig(delta, inv_alpha3, k_d, delta_cap) + w_d_rad_s * rho
    return radial * (1j * w_delta - w_z) + r_rate_m_s, z, delta
