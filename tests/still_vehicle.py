"""The one in-memory vehicle (agents.mavlink.vehicle.Vehicle) for a node on an in-memory bus:
at rest where it is put (by default (1, 2, 10) m ENU), heard, and it takes and keeps every
setpoint (the node's MAVLink side, without MAVLink)."""

from __future__ import annotations

from agents.mavlink.vehicle import Vehicle
from agents.mavlink.vehicle_types import VehicleState

STILL = VehicleState((1.0, 2.0, 10.0), (0.0, 0.0, 0.0), 0.0, True, "OFFBOARD", True)


class StillVehicle:
    def __init__(self, pos_enu_m: tuple[float, float, float] = STILL.pos_enu_m) -> None:
        self.state = VehicleState(pos_enu_m, (0.0, 0.0, 0.0), 0.0, True, "OFFBOARD", True)
        self.setpoints: list[tuple[float, float, float]] = []

    def poll(self) -> VehicleState:
        return self.state

    def send_velocity_enu(self, v: tuple[float, float, float]) -> bool:
        self.setpoints.append(v)
        return True


def still_vehicle() -> Vehicle:
    """A StillVehicle at STILL."""
    return StillVehicle()
