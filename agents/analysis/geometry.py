"""Small numpy geometric primitives: the metrics' included angles, plane/complex views."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from agents.law.enclosing import TWO_PI

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


def wrap_2pi(angle_rad: FloatArray) -> FloatArray:
    """Wrap angles into [0, 2 pi)."""
    return np.mod(angle_rad, TWO_PI)


def bearing(vec: FloatArray) -> FloatArray:
    """Angle of (..., 2) vectors from the x (east) axis, counter-clockwise."""
    return np.arctan2(vec[..., 1], vec[..., 0])


def included_angles(pos_m: FloatArray, succ_pos_m: FloatArray, center_m: FloatArray) -> FloatArray:
    """Angle from each follower to its successor seen from `center_m`, in [0, 2 pi).

    `center_m` is (..., 2) and broadcast against the positions: the true LAP for the
    real errors.
    """
    return wrap_2pi(bearing(succ_pos_m - center_m) - bearing(pos_m - center_m))


def as_complex(vec_m: FloatArray) -> ComplexArray:
    """(..., 2) float rows as (...) complex x + iy (a view when contiguous)."""
    return np.ascontiguousarray(vec_m, dtype=np.float64).view(np.complex128)[..., 0]


def as_plane(vec: ComplexArray) -> FloatArray:
    """(...) complex back to (..., 2) float rows, without copying."""
    return vec.view(np.float64).reshape(*vec.shape, 2)
