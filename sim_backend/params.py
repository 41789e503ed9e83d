"""A small per-vehicle parameter store answering the MAVLink parameter protocol.

PX4 sends integer parameters "bytewise" (the int32 bits reinterpreted as the
float field), ArduPilot casts them; SDKs decode according to the autopilot, so
the simulator does the same.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from agents.mavlink.modes import PX4
from agents.scenario.model import VehicleConfig

MAV_PARAM_TYPE_INT32 = 6
MAV_PARAM_TYPE_REAL32 = 9


@dataclass
class Param:
    value: float
    param_type: int


def default_params(flavour: str, sysid: int, cfg: VehicleConfig) -> dict[str, Param]:
    """Parameters SDKs and ground stations commonly read, typed as the real autopilot types them.

    Values the simulator obeys (take-off, RTL, failsafe and disarm times) are read back
    from here at start and after every PARAM_SET; the rest describe the vehicle.
    """
    real, integer = MAV_PARAM_TYPE_REAL32, MAV_PARAM_TYPE_INT32
    if flavour == PX4:
        return {
            "MAV_SYS_ID": Param(sysid, integer),
            "MAV_COMP_ID": Param(1, integer),
            "MAV_TYPE": Param(2, integer),
            "SYS_AUTOSTART": Param(4001, integer),
            "MIS_TAKEOFF_ALT": Param(2.5, real),
            # The documented choice: 0.5 s (PX4's default is 1.0 s).
            "COM_OF_LOSS_T": Param(0.5, real),
            "COM_OBL_RC_ACT": Param(0, integer),
            "COM_DISARM_PRFLT": Param(10.0, real),
            "COM_DISARM_LAND": Param(2.0, real),
            "COM_RC_IN_MODE": Param(4, integer),
            "NAV_DLL_ACT": Param(0, integer),
            "NAV_RCL_ACT": Param(0, integer),
            "RTL_RETURN_ALT": Param(10.0, real),
            "RTL_DESCEND_ALT": Param(10.0, real),
            "MPC_XY_VEL_MAX": Param(cfg.max_speed_xy_m_s, real),
            "MPC_XY_CRUISE": Param(min(5.0, cfg.max_speed_xy_m_s), real),
            "MPC_Z_VEL_MAX_UP": Param(cfg.max_speed_z_m_s, real),
            "MPC_Z_VEL_MAX_DN": Param(cfg.max_speed_z_m_s, real),
            "MPC_TKO_SPEED": Param(min(1.5, cfg.max_speed_z_m_s), real),
            "MPC_LAND_SPEED": Param(0.7, real),
        }
    return {
        "SYSID_THISMAV": Param(sysid, integer),
        "SYSID_MYGCS": Param(255, integer),
        "FRAME_CLASS": Param(1, integer),
        "FRAME_TYPE": Param(1, integer),
        "PILOT_TKOFF_ALT": Param(250.0, real),
        "GUID_TIMEOUT": Param(3.0, real),
        "DISARM_DELAY": Param(10, integer),
        "FS_GCS_ENABLE": Param(0, integer),
        "RTL_ALT": Param(1000.0, real),
        "WPNAV_SPEED": Param(cfg.max_speed_xy_m_s * 100.0, real),
        "WPNAV_SPEED_UP": Param(cfg.max_speed_z_m_s * 100.0, real),
        "WPNAV_SPEED_DN": Param(cfg.max_speed_z_m_s * 100.0, real),
        "LAND_SPEED": Param(70.0, real),
    }


class ParamStore:
    """Ordered name -> value store; `wire_value` gives the float to put in PARAM_VALUE."""

    def __init__(self, flavour: str, params: dict[str, Param]) -> None:
        self.flavour = flavour
        self._params = dict(params)
        self._names = list(self._params)

    def __len__(self) -> int:
        return len(self._names)

    def get(self, name: str) -> float:
        return self._params[name].value

    def name_at(self, index: int) -> str | None:
        return self._names[index] if 0 <= index < len(self._names) else None

    def index_of(self, name: str) -> int:
        return self._names.index(name) if name in self._params else -1

    def wire(self, name: str) -> tuple[float, int]:
        """(param_value field, param_type) as sent on the wire."""
        p = self._params[name]
        if p.param_type == MAV_PARAM_TYPE_INT32 and self.flavour == PX4:
            return struct.unpack("<f", struct.pack("<i", int(p.value)))[0], p.param_type
        return float(p.value), p.param_type

    def set_from_wire(self, name: str, wire_value: float, param_type: int) -> bool:
        """Store a PARAM_SET value; False (nothing changed) for unknown or non-finite values."""
        p = self._params.get(name)
        if p is None:
            return False
        if p.param_type == MAV_PARAM_TYPE_INT32 and self.flavour == PX4 \
                and param_type == MAV_PARAM_TYPE_INT32:
            p.value = float(struct.unpack("<i", struct.pack("<f", wire_value))[0])
            return True
        if not math.isfinite(wire_value):
            return False
        if p.param_type == MAV_PARAM_TYPE_INT32:
            if not -2**31 <= wire_value < 2**31:
                return False
            wire_value = float(round(wire_value))
        p.value = wire_value
        return True
