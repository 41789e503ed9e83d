"""The LAP estimator's laws for one follower on complex plane vectors, without numpy.

Twins of agents.core.estimator's (pinned by tests/unit/test_scalar_twins.py) and its
parameters: what the follower process runs, which must not import numpy (issue 15:
<= 50 MB per follower).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeVar

from agents.core.geometry_one import limited_sig_one, rate_cap

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    # A plane vector: a (2,) array, or x + iy (the networked follower's scalar twins).
    Vec = TypeVar("Vec", NDArray[np.float64], complex)
else:
    Vec = TypeVar("Vec")


@dataclass(frozen=True)
class EstimatorParams:
    """k_e and alpha1 of the paper; `step_fraction` caps one step's flow (0: plain Euler);
    `order` 2 adds the velocity stage (agents.scenario.model.Gains.estimator_order)."""

    k_e: float
    alpha1: float
    step_fraction: float = 0.5
    order: int = 1


def consensus_flows_c(
    r_self_m: complex,
    r_nbrs_m: Sequence[complex],
    nbr_fractions: Sequence[float],
    params: EstimatorParams,
    dt_s: float,
) -> list[complex]:
    """`consensus_flows` with plane vectors as complex x + iy (one list entry per link):
    the same law, component by component, without numpy's per-call cost."""
    base, exponent, gain = rate_cap(params.step_fraction, dt_s), 1.0 / params.alpha1, params.k_e
    flows = []
    for r_j, fraction in zip(r_nbrs_m, nbr_fractions, strict=True):
        gap, cap = r_j - r_self_m, base * fraction
        flows.append(complex(limited_sig_one(gap.real, exponent, gain, cap),
                             limited_sig_one(gap.imag, exponent, gain, cap)))
    return flows


def link_balance_c(own_sums_m: Sequence[complex], their_sums_m: Sequence[complex]) -> complex:
    """`link_balance` with plane vectors as complex x + iy, one per link."""
    total = 0j
    for own, theirs in zip(own_sums_m, their_sums_m, strict=True):
        total += own - theirs
    return 0.5 * total


def finite_difference_velocity(
    prev_pos_m: Vec,
    prev_stamp_s: float,
    pos_m: Vec,
    stamp_s: float,
    prev_vel_m_s: Vec,
    tau_s: float = 0.0,
) -> Vec:
    """Velocity from two timestamped observations, optionally low-passed with time constant tau.

    A zero or negative stamp difference (duplicate or reordered data) keeps the old estimate.
    Vectors are (2,) arrays or complex x + iy: plain arithmetic, the same for both.
    """
    dt = stamp_s - prev_stamp_s
    if dt <= 0.0:
        return prev_vel_m_s
    raw = (pos_m - prev_pos_m) / dt
    if tau_s <= 0.0:
        return raw
    gain = dt / (tau_s + dt)
    return prev_vel_m_s + gain * (raw - prev_vel_m_s)


def lag_free_velocity(
    prev_pos_m: Vec,
    prev_stamp_s: float,
    pos_m: Vec,
    stamp_s: float,
    smooth_m_s: Vec,
    accel_m_s2: Vec,
    tau_s: float,
    accel_tau_s: float,
) -> tuple[Vec, Vec, Vec]:
    """(velocity, smooth, accel): `finite_difference_velocity` (over the stamps' gap, so
    true at its midpoint; `smooth_m_s` its last value), corrected for what its low-pass
    costs an accelerating target.  The stamps must increase.

    The low-passed velocity trails a constant acceleration a by a * (tau + dt / 2): on a
    20 Hz sensor with tau = 0.1 s, a target swinging at 0.05 m/s^2 reads 6 mm/s off, and
    only the followers that see it feed that forward (ring64's halves drift apart on it,
    issue 15).  The acceleration, itself low-passed with `accel_tau_s` (so noise and a
    start from rest do not ring the velocity much), puts that lag back: exact for a constant
    acceleration, and for a slow sinusoid within its phase lag.
    """
    dt = stamp_s - prev_stamp_s
    smooth = finite_difference_velocity(prev_pos_m, prev_stamp_s, pos_m, stamp_s, smooth_m_s,
                                        tau_s)
    accel = accel_m_s2 + dt / (accel_tau_s + dt) * ((smooth - smooth_m_s) / dt - accel_m_s2)
    return smooth + accel * (tau_s + 0.5 * dt), smooth, accel
