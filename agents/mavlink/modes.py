"""Flight-mode numbers of PX4 and ArduPilot copter, shared by the adapter and the simulator.

PX4 packs its mode as custom_mode = main << 16 | sub << 24; ArduPilot copter uses
one plain number.  Code everywhere else speaks mode *names*.
"""

from __future__ import annotations

import math
from typing import Final

PX4: Final = "px4"
ARDUPILOT: Final = "ardupilot"
FLAVOURS: Final = (PX4, ARDUPILOT)

MAV_AUTOPILOT_ARDUPILOTMEGA: Final = 3
MAV_AUTOPILOT_PX4: Final = 12
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED: Final = 1
MAV_MODE_FLAG_SAFETY_ARMED: Final = 128

# name -> (main, sub)
PX4_MODES: Final[dict[str, tuple[int, int]]] = {
    "MANUAL": (1, 0),
    "ALTCTL": (2, 0),
    "POSCTL": (3, 0),
    "READY": (4, 1),
    "TAKEOFF": (4, 2),
    "HOLD": (4, 3),
    "MISSION": (4, 4),
    "RTL": (4, 5),
    "LAND": (4, 6),
    "ACRO": (5, 0),
    "OFFBOARD": (6, 0),
    "STABILIZED": (7, 0),
}

ARDUPILOT_MODES: Final[dict[str, int]] = {
    "STABILIZE": 0,
    "ACRO": 1,
    "ALT_HOLD": 2,
    "AUTO": 3,
    "GUIDED": 4,
    "LOITER": 5,
    "RTL": 6,
    "LAND": 9,
    "POSHOLD": 16,
    "BRAKE": 17,
}

# The mode that flies external velocity setpoints, and the one a vehicle falls back to.
OFFBOARD_MODE: Final = {PX4: "OFFBOARD", ARDUPILOT: "GUIDED"}
HOLD_MODE: Final = {PX4: "HOLD", ARDUPILOT: "LOITER"}
LAND_MODE: Final = {PX4: "LAND", ARDUPILOT: "LAND"}
INITIAL_MODE: Final = {PX4: "HOLD", ARDUPILOT: "STABILIZE"}


def flavour_of_autopilot(autopilot: int) -> str | None:
    """The flavour a HEARTBEAT's autopilot field announces, or None for anything else."""
    return {MAV_AUTOPILOT_PX4: PX4, MAV_AUTOPILOT_ARDUPILOTMEGA: ARDUPILOT}.get(autopilot)


def autopilot_of_flavour(flavour: str) -> int:
    return MAV_AUTOPILOT_PX4 if flavour == PX4 else MAV_AUTOPILOT_ARDUPILOTMEGA


def encode_custom_mode(flavour: str, name: str) -> int:
    """custom_mode of a HEARTBEAT for a mode name; KeyError for a name the flavour lacks."""
    if flavour == PX4:
        main, sub = PX4_MODES[name]
        return (main << 16) | (sub << 24)
    return ARDUPILOT_MODES[name]


def decode_custom_mode(flavour: str, custom_mode: int) -> str:
    """Mode name of a HEARTBEAT custom_mode (``UNKNOWN(<n>)`` when not in the table)."""
    if flavour == PX4:
        main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
        for name, (m, s) in PX4_MODES.items():
            if m == main and (s == sub or (main != 4 and sub == 0)):
                return name
        return f"UNKNOWN({custom_mode})"
    for name, number in ARDUPILOT_MODES.items():
        if number == custom_mode:
            return name
    return f"UNKNOWN({custom_mode})"


def do_set_mode_params(flavour: str, name: str) -> tuple[float, float, float]:
    """param1..3 of MAV_CMD_DO_SET_MODE (176) selecting `name`."""
    if flavour == PX4:
        main, sub = PX4_MODES[name]
        return (float(MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(main), float(sub))
    return (float(MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(ARDUPILOT_MODES[name]), 0.0)


def _exact_int(value: float) -> int | None:
    """value as an int when it is a finite whole number in 0..2**31-1, else None (NaN, inf, 1.5)."""
    if not math.isfinite(value) or value != int(value) or not 0 <= value < 2**31:
        return None
    return int(value)


def mode_of_do_set_mode(flavour: str, param1: float, param2: float, param3: float) -> str | None:
    """The mode name DO_SET_MODE asks for, or None when the request names no known mode.

    Never raises: NaN, inf and fractions (SDKs fill unused fields with NaN) name no mode,
    except a NaN sub-mode, which MAVLink allows to mean "unused" (read as 0).
    """
    base, main = _exact_int(param1), _exact_int(param2)
    sub = 0 if math.isnan(param3) else _exact_int(param3)
    if base is None or main is None or sub is None or not base & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        return None
    if flavour == PX4:
        for name, (m, s) in PX4_MODES.items():
            if m == main and (s == sub or (main != 4 and sub == 0)):
                return name
        # A bare AUTO request (sub 0) means "continue in auto", which PX4 maps to HOLD here.
        return "HOLD" if main == 4 and sub == 0 else None
    for name, number in ARDUPILOT_MODES.items():
        if number == main:
            return name
    return None


def known_mode(flavour: str, name: str) -> bool:
    """True when `name` is in the flavour's mode table (so encode_custom_mode cannot fail)."""
    return name in (PX4_MODES if flavour == PX4 else ARDUPILOT_MODES)
