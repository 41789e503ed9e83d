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
    delta_cap = (0.5 * rate_cap(gains.step_fraction, max(dt_s, succ_age_s))) * rho * angle_rad
    w_delta = (limited_sig_one(delta, 1.0 / gains.alpha3, gains.k_d, delta_cap)
               + gains.w_d_rad_s * rho)
    return radial * (1j * w_delta - w_z) + r_rate_m_s, z, delta
