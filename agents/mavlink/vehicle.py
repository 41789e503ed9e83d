"""What a node needs of its vehicle: its latest state, and a velocity setpoint sent.

A follower or target node depends on this, not on the MAVLink adapter
(agents.mavlink.adapter.MavlinkAdapter is the one shipped implementation), so that a node
runs on whatever vehicle it is handed: tests/still_vehicle.py is the in-memory one.
"""

from __future__ import annotations

from typing import Protocol

from agents.mavlink.vehicle_types import VehicleState


class Vehicle(Protocol):
    def poll(self) -> VehicleState:
        """The latest known state (link_ok False when the vehicle is not heard)."""
        ...

    def send_velocity_enu(self, v: tuple[float, float, float]) -> bool:
        """Send an ENU velocity setpoint in m/s; False when it was not sent."""
        ...
