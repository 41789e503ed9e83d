"""Small geometric primitives shared by the estimator, the controller and the metrics."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

# The float twins (numpy-free, for the follower process) and the constants both use.
from agents.core.geometry_one import NO_CAP_PER_S as NO_CAP_PER_S
from agents.core.geometry_one import TWO_PI as TWO_PI
from agents.core.geometry_one import limited_sig_one as limited_sig_one
from agents.core.geometry_one import rate_cap as rate_cap

FloatArray = NDArray[np.float64]


def sig(x: FloatArray, exponent: float) -> FloatArray:
    """sig(x)^a = sign(x) * |x|^a, elementwise (the paper's odd-ratio power)."""
    if exponent == 1.0 / 3.0:
        return np.cbrt(x)  # exact and one call: the paper's alpha = 3
    return np.copysign(np.abs(x) ** exponent, x)


def wrap_2pi(angle_rad: FloatArray) -> FloatArray:
    """Wrap angles into [0, 2 pi)."""
    return np.mod(angle_rad, TWO_PI)


def bearing(vec: FloatArray) -> FloatArray:
    """Angle of (..., 2) vectors from the x (east) axis, counter-clockwise."""
    return np.arctan2(vec[..., 1], vec[..., 0])


def included_angles(pos_m: FloatArray, succ_pos_m: FloatArray, center_m: FloatArray) -> FloatArray:
    """Angle from each follower to its successor seen from `center_m`, in [0, 2 pi).

    `center_m` is (..., 2) and broadcast against the positions: the true LAP for the
    real errors, each follower's own estimate r_i for the controller.
    """
    return wrap_2pi(bearing(succ_pos_m - center_m) - bearing(pos_m - center_m))


def rotate_ccw(vec: FloatArray) -> FloatArray:
    """(..., 2) vectors rotated by +90 degrees."""
    out = np.empty_like(vec)
    out[..., 0] = -vec[..., 1]
    out[..., 1] = vec[..., 0]
    return out


def limited_sig(
    x: FloatArray, exponent: float, gain: float, rate_cap_per_s: FloatArray | float
) -> FloatArray:
    """gain * sig(x)^a, its magnitude capped at rate_cap_per_s * |x|.

    A law with a < 1 has unbounded gain near zero, so an explicit step of dt
    overshoots zero and settles into a 2-cycle (the numerical dithering the paper
    claims to avoid).  Capping the rate at fraction/dt * |x| lets one step remove
    at most that fraction of the error; as dt -> 0 the cap vanishes and the law
    is the paper's.  `NO_CAP_PER_S` gives the plain law (geometry_one: `rate_cap`).
    """
    mag = np.abs(x)
    return np.copysign(np.minimum(gain * mag**exponent, rate_cap_per_s * mag), x)
