"""type_mask decoding of SET_POSITION_TARGET_LOCAL_NED, frames, non-finite fields."""

from __future__ import annotations

import math

import pytest

from sim_backend.setpoint import SetpointRejected, decode_setpoint

HERE = (10.0, 20.0, -5.0)


def dec(mask: int, frame: int = 1, pos=(1.0, 2.0, 3.0), vel=(4.0, 5.0, 6.0), yaw=0.7,
        rate=0.3, vehicle_yaw=0.0):
    return decode_setpoint(mask, frame, pos, vel, yaw, rate, HERE, vehicle_yaw)


def test_velocity_only_3527() -> None:
    sp = dec(3527)
    assert sp.pos_axis == (False, False, False)
    assert sp.vel_ned_m_s == (4.0, 5.0, 6.0)
    assert sp.yaw_rad is None and sp.yaw_rate_rad_s is None


def test_velocity_and_yaw_2503() -> None:
    sp = dec(2503)
    assert sp.vel_ned_m_s == (4.0, 5.0, 6.0) and sp.yaw_rad == 0.7 and sp.yaw_rate_rad_s is None


def test_velocity_and_yaw_rate_1479() -> None:
    sp = dec(1479)
    assert sp.yaw_rad is None and sp.yaw_rate_rad_s == 0.3


def test_force_bit_is_ignored_4039() -> None:
    assert dec(4039) == dec(3527)


def test_position_axes_and_unused_velocity_axis() -> None:
    sp = dec(0b110111111000)  # position only
    assert sp.pos_axis == (True, True, True) and sp.pos_ned_m == (1.0, 2.0, 3.0)
    sp = dec(3527 | (1 << 5))  # vz ignored -> 0
    assert sp.vel_ned_m_s == (4.0, 5.0, 0.0)


def test_body_frame_rotates_by_heading() -> None:
    sp = dec(3527, frame=8, vel=(1.0, 0.0, 0.5), vehicle_yaw=math.pi / 2)
    assert sp.vel_ned_m_s == pytest.approx((0.0, 1.0, 0.5))
    assert dec(3527, frame=9, vel=(1.0, 0.0, 0.5), vehicle_yaw=math.pi / 2) == sp


def test_offset_frames_add_vehicle_position() -> None:
    sp = dec(0b110111111000, frame=7)
    assert sp.pos_ned_m == (11.0, 22.0, -2.0)
    assert dec(3527, frame=7).vel_ned_m_s == (4.0, 5.0, 6.0)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_used_field_rejected(bad: float) -> None:
    with pytest.raises(SetpointRejected, match="finite"):
        dec(3527, vel=(bad, 0.0, 0.0))
    with pytest.raises(SetpointRejected, match="finite"):
        dec(2503, yaw=bad)


def test_non_finite_unused_field_is_fine() -> None:
    assert dec(3527, pos=(math.nan,) * 3, yaw=math.nan).vel_ned_m_s == (4.0, 5.0, 6.0)


def test_unsupported_frame_and_empty_mask() -> None:
    with pytest.raises(SetpointRejected):
        dec(3527, frame=0)
    with pytest.raises(SetpointRejected):
        dec(0xFFF)
