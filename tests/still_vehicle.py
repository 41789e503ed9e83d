"""A vehicle for a FollowerNode on an in-memory bus: at rest at (1, 2, 10) m ENU, heard,
and it takes every setpoint (the node's MAVLink side, without MAVLink)."""

from __future__ import annotations

from typing import Any, cast

from agents.mavlink.adapter import MavlinkAdapter
from agents.mavlink.vehicle_types import VehicleState

STILL = VehicleState((1.0, 2.0, 10.0), (0.0, 0.0, 0.0), 0.0, True, "OFFBOARD", True)


class StillVehicle:
    def poll(self) -> VehicleState:
        return STILL

    def send_velocity_enu(self, v: tuple[float, float, float]) -> bool:
        return True


def still_vehicle() -> MavlinkAdapter:
    """A StillVehicle where the node wants its adapter."""
    return cast(MavlinkAdapter, cast(Any, StillVehicle()))
