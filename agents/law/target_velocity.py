"""A target's velocity from its timestamped observations (the followers do not know it).

The controller feeds dr_i/dt = dPhi_i/dt + dp~_i/dt forward, and dp~_i/dt needs the
observed targets' velocities: each follower estimates them from the positions it
observes.  Plain arithmetic on plane vectors: complex x + iy (the follower) or (2,)
arrays (the numpy reference tick), the same for both.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeVar

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    Vec = TypeVar("Vec", NDArray[np.float64], complex)
else:
    Vec = TypeVar("Vec")


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
