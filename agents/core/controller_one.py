"""The enclosing controller for one follower on complex plane vectors, without numpy.

The twin of agents.core.controller.enclosing_control (pinned by
tests/unit/test_scalar_twins.py) and its gains: what the follower process runs, which
must not import numpy (issue 15: <= 50 MB per follower).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from agents.core.geometry_one import TWO_PI, limited_sig_one, rate_cap

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
    # Largest product of the spacing law's linear gain and its successor's data age
    # (Gains.spacing_gain_age; None: step_fraction / 2, one step's share per age).
    spacing_gain_age: float | None = None


def spacing_step_s(gains: ControlGains, dt_s: float, succ_age_s: float) -> float:
    """The step the angle's cap is computed for: dt, stretched by the successor's data age.

    Near zero the spacing law is linear with gain g = step_fraction / (2 dt) (half the cap:
    the successor's own correction moves delta too).  Correcting on data of age L with
    g L large oscillates, so the gain is cut to spacing_gain_age / L where g L would
    exceed it; by default that is at any age beyond a period."""
    limit = gains.spacing_gain_age
    if limit is None or gains.step_fraction <= 0.0:
        return max(dt_s, succ_age_s)
    return max(dt_s, succ_age_s * 0.5 * gains.step_fraction / limit)


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
    # The gap wraps to within half a turn of the desired angle, not to [0, 2 pi): a
    # successor fallen just behind (the order inverted: a vehicle held still while the
    # ring turned) reads as a negative gap and is waited for, instead of chased round
    # the whole ring into a wound formation.  Orders that never invert see the paper's.
    delta = ((math.atan2(turn.imag, turn.real) - angle_rad + math.pi) % TWO_PI - math.pi) \
        / angle_rad
    cap = rate_cap(gains.step_fraction, dt_s)
    w_z = limited_sig_one(z, 1.0 / gains.alpha2, gains.k_z, cap)
    step_s = spacing_step_s(gains, dt_s, succ_age_s)
    delta_cap = (0.5 * rate_cap(gains.step_fraction, step_s)) * rho * angle_rad
    w_delta = (limited_sig_one(delta, 1.0 / gains.alpha3, gains.k_d, delta_cap)
               + gains.w_d_rad_s * rho)
    return radial * (1j * w_delta - w_z) + r_rate_m_s, z, delta
