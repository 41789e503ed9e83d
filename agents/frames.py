"""The one place where ENU (scenario, algorithm) and NED (MAVLink, autopilot) meet.

The algorithm works in a local East-North-Up plane: x east, y north.  MAVLink
LOCAL_NED is x north, y east, z down.  Swapping the first two axes and negating
the third converts either way (the map is its own inverse).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def enu_to_ned(vec_enu: FloatArray) -> FloatArray:
    """Convert (..., 3) ENU vectors to NED."""
    vec = np.asarray(vec_enu, dtype=np.float64)
    return np.stack([vec[..., 1], vec[..., 0], -vec[..., 2]], axis=-1)


def ned_to_enu(vec_ned: FloatArray) -> FloatArray:
    """Convert (..., 3) NED vectors to ENU."""
    vec = np.asarray(vec_ned, dtype=np.float64)
    return np.stack([vec[..., 1], vec[..., 0], -vec[..., 2]], axis=-1)
