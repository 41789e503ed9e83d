"""Mode numbers of both flavours and ENU <-> NED conversions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.frames import (
    enu_to_ned,
    enu_to_ned_xyz,
    ned_to_enu,
    ned_to_enu_xyz,
    yaw_enu_to_ned,
    yaw_ned_to_enu,
)
from agents.mavlink import modes


def test_px4_custom_mode_layout() -> None:
    assert modes.encode_custom_mode("px4", "OFFBOARD") == 0x60000
    assert modes.encode_custom_mode("px4", "HOLD") == (4 << 16) | (3 << 24)
    assert modes.decode_custom_mode("px4", 0x60000) == "OFFBOARD"
    assert modes.decode_custom_mode("px4", (4 << 16) | (6 << 24)) == "LAND"
    assert modes.decode_custom_mode("px4", 99 << 16).startswith("UNKNOWN")


def test_ardupilot_numbers() -> None:
    assert modes.encode_custom_mode("ardupilot", "GUIDED") == 4
    assert modes.decode_custom_mode("ardupilot", 9) == "LAND"


@pytest.mark.parametrize("flavour", modes.FLAVOURS)
def test_do_set_mode_round_trip(flavour: str) -> None:
    table = modes.PX4_MODES if flavour == "px4" else modes.ARDUPILOT_MODES
    for name in table:
        assert modes.mode_of_do_set_mode(flavour, *modes.do_set_mode_params(flavour, name)) == name
    assert modes.mode_of_do_set_mode(flavour, 0.0, 4.0, 0.0) is None


def test_flavour_from_heartbeat_autopilot() -> None:
    assert modes.flavour_of_autopilot(12) == "px4"
    assert modes.flavour_of_autopilot(3) == "ardupilot"
    assert modes.flavour_of_autopilot(8) is None


def test_enu_ned_vectors() -> None:
    enu = np.array([1.0, 2.0, 3.0])
    assert enu_to_ned(enu).tolist() == [2.0, 1.0, -3.0]
    assert ned_to_enu(enu_to_ned(enu)).tolist() == enu.tolist()


def test_scalar_twins_equal_the_array_conversions() -> None:
    for vec in ([1.0, 2.0, 3.0], [-0.5, 7.25, -1e-3], [0.0, -0.0, 1e9]):
        assert list(enu_to_ned_xyz(*vec)) == enu_to_ned(np.array(vec)).tolist()
        assert list(ned_to_enu_xyz(*vec)) == ned_to_enu(np.array(vec)).tolist()


def test_yaw_conversion() -> None:
    assert yaw_enu_to_ned(0.0) == pytest.approx(math.pi / 2)  # facing east
    assert yaw_enu_to_ned(math.pi / 2) == pytest.approx(0.0)  # facing north
    for yaw in np.linspace(-3.0, 3.0, 13):
        assert yaw_ned_to_enu(yaw_enu_to_ned(float(yaw))) == pytest.approx(float(yaw))
