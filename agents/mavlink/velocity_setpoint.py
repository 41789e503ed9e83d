"""A velocity setpoint as SET_POSITION_TARGET_LOCAL_NED fields, in wire order: pure.

The agent thinks in ENU; the vehicle takes NED (agents.frames).  The type mask tells the
autopilot to fly the velocity (and the yaw, when one is given) and ignore the rest, as
PX4's offboard and ArduPilot's guided mode read it.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from agents.frames import enu_to_ned_xyz, yaw_enu_to_ned

if TYPE_CHECKING:  # the follower's process runs without numpy (issue 15)
    import numpy as np

MAV_FRAME_LOCAL_NED = 1
MASK_VELOCITY = 3527
MASK_VELOCITY_YAW = 2503


def velocity_fields(vel_enu_m_s: tuple[float, float, float] | np.ndarray,
                    yaw_enu_rad: float | None, boot_ms: int, sysid: int,
                    ) -> tuple[float | int, ...] | None:
    """The fields of SET_POSITION_TARGET_LOCAL_NED for (sysid, component 1), or None when
    the velocity is not three finite numbers or the yaw is not finite."""
    vel = _three_floats(vel_enu_m_s)
    if vel is None or not math.isfinite(vel[0] + vel[1] + vel[2]) or \
            (yaw_enu_rad is not None and not math.isfinite(yaw_enu_rad)):
        return None
    vn, ve, vd = enu_to_ned_xyz(*vel)
    mask = MASK_VELOCITY if yaw_enu_rad is None else MASK_VELOCITY_YAW
    yaw = 0.0 if yaw_enu_rad is None else yaw_enu_to_ned(yaw_enu_rad)
    return (boot_ms, 0.0, 0.0, 0.0, vn, ve, vd, 0.0, 0.0, 0.0, yaw, 0.0, mask, sysid, 1,
            MAV_FRAME_LOCAL_NED)


def _three_floats(vec: tuple[float, float, float] | np.ndarray,
                  ) -> tuple[float, float, float] | None:
    """A 3-vector as floats, or None when it is not one."""
    try:
        x, y, z = vec
        return float(x), float(y), float(z)
    except (TypeError, ValueError):
        return None
