"""The one place where ENU (scenario, algorithm) and NED (MAVLink, autopilot) meet.

The algorithm works in a local East-North-Up plane: x east, y north.  MAVLink
LOCAL_NED is x north, y east, z down.  Swapping the first two axes and negating
the third converts either way (the map is its own inverse).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

# numpy only for arrays of vectors (simulator, recorder): the follower's MAVLink adapter
# uses the float versions and its process must not import numpy (issue 15).
if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    FloatArray = NDArray[np.float64]


def enu_to_ned(vec_enu: FloatArray) -> FloatArray:
    """Convert (..., 3) ENU vectors to NED."""
    import numpy as np

    vec = np.asarray(vec_enu, dtype=np.float64)
    return np.stack([vec[..., 1], vec[..., 0], -vec[..., 2]], axis=-1)


def ned_to_enu(vec_ned: FloatArray) -> FloatArray:
    """Convert (..., 3) NED vectors to ENU."""
    import numpy as np

    vec = np.asarray(vec_ned, dtype=np.float64)
    return np.stack([vec[..., 1], vec[..., 0], -vec[..., 2]], axis=-1)


def enu_to_ned_xyz(x: float, y: float, z: float) -> tuple[float, float, float]:
    """One ENU vector as three floats to NED, without numpy: `enu_to_ned` for the
    per-message MAVLink path, where an array costs more than the whole conversion."""
    return (y, x, -z)


def ned_to_enu_xyz(x: float, y: float, z: float) -> tuple[float, float, float]:
    """One NED vector as three floats to ENU (`ned_to_enu` without numpy)."""
    return (y, x, -z)


def yaw_enu_to_ned(yaw_enu_rad: float) -> float:
    """ENU yaw (counter-clockwise from east) to NED yaw (clockwise from north), in (-pi, pi]."""
    return wrap_pi(0.5 * math.pi - yaw_enu_rad)


def yaw_ned_to_enu(yaw_ned_rad: float) -> float:
    """NED yaw to ENU yaw; the map is its own inverse."""
    return wrap_pi(0.5 * math.pi - yaw_ned_rad)


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    wrapped = math.atan2(math.sin(angle_rad), math.cos(angle_rad))
    return math.pi if wrapped == -math.pi else wrapped
