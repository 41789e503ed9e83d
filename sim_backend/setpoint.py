"""Decode SET_POSITION_TARGET_LOCAL_NED into a setpoint in the local NED frame.

type_mask is read bit by bit (bit set = field ignored): 0-2 position, 3-5
velocity, 6-8 acceleration (not flown by this model), 9 force (ignored, ground
stations set it), 10 yaw, 11 yaw rate.  An axis with its position bit clear is
position-controlled, else velocity-controlled (velocity 0 when that bit is set too).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_LOCAL_OFFSET_NED = 7
MAV_FRAME_BODY_NED = 8
MAV_FRAME_BODY_OFFSET_NED = 9
SUPPORTED_FRAMES = (MAV_FRAME_LOCAL_NED, MAV_FRAME_LOCAL_OFFSET_NED, MAV_FRAME_BODY_NED,
                    MAV_FRAME_BODY_OFFSET_NED)

YAW_BIT = 10
YAW_RATE_BIT = 11


class SetpointRejected(ValueError):
    """The message asks for nothing this model flies, or carries a non-finite used field."""


@dataclass(frozen=True)
class Setpoint:
    """A decoded setpoint in local NED; yaw fields are None when not commanded."""

    pos_axis: tuple[bool, bool, bool]
    pos_ned_m: tuple[float, float, float]
    vel_ned_m_s: tuple[float, float, float]
    yaw_rad: float | None
    yaw_rate_rad_s: float | None


def _bit(mask: int, bit: int) -> bool:
    return bool(mask >> bit & 1)


@functools.lru_cache(maxsize=1024)
def _mask_fields(type_mask: int) -> tuple[tuple[bool, bool, bool], tuple[bool, bool, bool],
                                         bool, bool]:
    """(position axes, velocity axes, yaw, yaw rate) a type_mask uses; senders stream one
    mask over and over, so each is read bit by bit once."""
    pos_axis = (not _bit(type_mask, 0), not _bit(type_mask, 1), not _bit(type_mask, 2))
    vel_axis = (not _bit(type_mask, 3), not _bit(type_mask, 4), not _bit(type_mask, 5))
    return pos_axis, vel_axis, not _bit(type_mask, YAW_BIT), not _bit(type_mask, YAW_RATE_BIT)


def _rotate_yaw(vec: tuple[float, float, float], yaw_rad: float) -> tuple[float, float, float]:
    """Body (forward, right, down) to NED by heading only, as PX4 and ArduPilot do."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return (c * vec[0] - s * vec[1], s * vec[0] + c * vec[1], vec[2])


def _pick(vec: tuple[float, float, float], used: tuple[bool, ...]) -> tuple[float, float, float]:
    """The used components (the others 0); raises SetpointRejected if one is not finite."""
    out = (vec[0] if used[0] else 0.0, vec[1] if used[1] else 0.0, vec[2] if used[2] else 0.0)
    if not (math.isfinite(out[0]) and math.isfinite(out[1]) and math.isfinite(out[2])):
        raise SetpointRejected("non-finite field")
    return out


def decode_setpoint(type_mask: int, frame: int, pos: tuple[float, float, float],
                    vel: tuple[float, float, float], yaw_rad: float, yaw_rate_rad_s: float,
                    vehicle_pos_ned_m: tuple[float, float, float],
                    vehicle_yaw_rad: float) -> Setpoint:
    """The setpoint a message asks for; raises SetpointRejected for one to drop and count."""
    if frame not in SUPPORTED_FRAMES:
        raise SetpointRejected(f"frame {frame}")
    pos_axis, vel_axis, use_yaw, use_rate = _mask_fields(type_mask)
    if not (True in pos_axis or True in vel_axis or use_yaw or use_rate):
        raise SetpointRejected("type_mask ignores every field this model flies")
    pos_used = _pick(pos, pos_axis)
    vel_used = _pick(vel, vel_axis)
    if (use_yaw and not math.isfinite(yaw_rad)) or \
            (use_rate and not math.isfinite(yaw_rate_rad_s)):
        raise SetpointRejected("non-finite field")
    if frame != MAV_FRAME_LOCAL_NED:
        if frame in (MAV_FRAME_BODY_NED, MAV_FRAME_BODY_OFFSET_NED):
            vel_used = _rotate_yaw(vel_used, vehicle_yaw_rad)
            pos_used = _rotate_yaw(pos_used, vehicle_yaw_rad)
        pos_used = (pos_used[0] + vehicle_pos_ned_m[0], pos_used[1] + vehicle_pos_ned_m[1],
                    pos_used[2] + vehicle_pos_ned_m[2])
    return Setpoint(
        pos_axis=pos_axis,
        pos_ned_m=pos_used,
        vel_ned_m_s=vel_used,
        yaw_rad=yaw_rad if use_yaw else None,
        yaw_rate_rad_s=yaw_rate_rad_s if use_rate and not use_yaw else None,
    )
