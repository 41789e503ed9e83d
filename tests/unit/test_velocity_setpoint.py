"""agents.mavlink.velocity_setpoint: ENU in, NED fields out, anything not finite refused."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agents.mavlink.lean_common import MAVLink_set_position_target_local_ned_message as Setpoint
from agents.mavlink.velocity_setpoint import MASK_VELOCITY, MASK_VELOCITY_YAW, velocity_fields

pytestmark = pytest.mark.timeout(60)
finite = st.floats(-1e6, 1e6)


@given(finite, finite, finite, st.one_of(st.none(), st.floats(-10.0, 10.0)))
def test_enu_velocity_is_flown_as_ned_with_the_mask_for_what_is_given(
        e: float, n: float, u: float, yaw: float | None) -> None:
    fields = velocity_fields((e, n, u), yaw, 1234, 7)
    assert fields is not None
    named = dict(zip(Setpoint.ordered_fieldnames, fields, strict=True))
    assert (named["vx"], named["vy"], named["vz"]) == (n, e, -u)
    assert named["type_mask"] == (MASK_VELOCITY if yaw is None else MASK_VELOCITY_YAW)
    assert (named["target_system"], named["target_component"], named["coordinate_frame"],
            named["time_boot_ms"]) == (7, 1, 1, 1234)
    Setpoint.unpacker.pack(*fields)  # every field fits its wire type


@pytest.mark.parametrize(("vel", "yaw"), [
    ((math.nan, 0.0, 0.0), None), ((0.0, math.inf, 0.0), None), ((0.0, 0.0, 0.0), math.nan),
    ((1.0, 2.0), None), ("abc", None), (None, None), ((1.0, "x", 2.0), None),
])
def test_anything_but_three_finite_numbers_is_refused(vel: object, yaw: float | None) -> None:
    assert velocity_fields(vel, yaw, 0, 1) is None  # type: ignore[arg-type]
