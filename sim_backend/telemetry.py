"""Telemetry messages of one simulated vehicle, built from one row of the fleet state."""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from operator import itemgetter
from typing import Any, NamedTuple

from pymavlink.dialects.v20 import common as mavlink2

from agents.mavlink.modes import (
    MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    MAV_MODE_FLAG_SAFETY_ARMED,
    PX4,
    autopilot_of_flavour,
    encode_custom_mode,
)
from agents.mavlink.wire import encode_fields, encode_payload
from agents.scenario.model import HomeConfig

MSG_HEARTBEAT = 0
MSG_SYS_STATUS = 1
MSG_GPS_RAW_INT = 24
MSG_VFR_HUD = 74
MSG_BATTERY_STATUS = 147
MSG_PROTOCOL_VERSION = 300
MSG_ATTITUDE = 30
MSG_LOCAL_POSITION_NED = 32
MSG_GLOBAL_POSITION_INT = 33
MSG_AUTOPILOT_VERSION = 148
MSG_HOME_POSITION = 242
MSG_EXTENDED_SYS_STATE = 245

EARTH_RADIUS_M = 6_378_137.0
MAV_TYPE_QUADROTOR = 2
MAV_STATE_STANDBY, MAV_STATE_ACTIVE = 3, 4
LANDED_ON_GROUND, LANDED_IN_AIR, LANDED_TAKEOFF, LANDED_LANDING = 1, 2, 3, 4
# gyro, accel, mag, baro, GPS and the pre-arm check bit: present, enabled and healthy.
SENSORS_OK = 1 | 2 | 4 | 8 | 32 | 0x10000000
# MISSION_INT (missions are stored, not flown), PARAM_FLOAT, COMMAND_INT,
# SET_POSITION_TARGET_LOCAL_NED, MAVLINK2; plus how integer parameters travel (PX4 bytewise,
# ArduPilot C cast).  No FTP: MAVFTP requests get a NAK so clients fall back at once.
CAPABILITIES = 4 | 2 | 8 | 128 | 8192
PARAM_ENCODING = {PX4: 16, "ardupilot": 131072}
SW_VERSION = {PX4: (1 << 24) | (14 << 16) | 255, "ardupilot": (4 << 24) | (5 << 16) | 255}


class Row(NamedTuple):
    """One vehicle at one tick (NED, SI units); immutable, and built for every vehicle every
    tick: a named tuple is made several times faster than a frozen dataclass."""

    time_boot_ms: int
    pos: tuple[float, float, float]
    vel: tuple[float, float, float]
    roll: float
    pitch: float
    yaw: float
    yaw_rate: float
    landed: bool


def geodetic(home: HomeConfig, north_m: float, east_m: float) -> tuple[int, int]:
    """lat, lon in degE7 of a local offset (flat earth: fine over a few km)."""
    lat = home.lat_deg + math.degrees(north_m / EARTH_RADIUS_M)
    east_radius_m = EARTH_RADIUS_M * math.cos(math.radians(home.lat_deg))
    lon = home.lon_deg + math.degrees(east_m / east_radius_m)
    return round(lat * 1e7), round(lon * 1e7)


def local_of_geodetic(home: HomeConfig, lat_deg: float, lon_deg: float) -> tuple[float, float]:
    """north, east in m of a lat/lon (the inverse of `geodetic`)."""
    north_m = math.radians(lat_deg - home.lat_deg) * EARTH_RADIUS_M
    east_radius_m = EARTH_RADIUS_M * math.cos(math.radians(home.lat_deg))
    return north_m, math.radians(lon_deg - home.lon_deg) * east_radius_m


def landed_state(row: Row, mode: str, armed: bool) -> int:
    if row.landed:
        return LANDED_ON_GROUND
    if mode == "LAND" and armed:
        return LANDED_LANDING
    return LANDED_TAKEOFF if mode == "TAKEOFF" else LANDED_IN_AIR


PROTOCOL_VERSION_CRC_EXTRA = 217


def protocol_version(mav: mavlink2.MAVLink) -> bytes:
    """PROTOCOL_VERSION (300): MAVLink 2 (version 200, min 100, max 200), no hashes."""
    payload = struct.pack("<HHH8B8B", 200, 100, 200, *([0] * 16))
    return encode_payload(mav, MSG_PROTOCOL_VERSION, PROTOCOL_VERSION_CRC_EXTRA, payload)


FAST_IDS = (MSG_LOCAL_POSITION_NED, MSG_ATTITUDE, MSG_GLOBAL_POSITION_INT)


def fast_bytes(mav: mavlink2.MAVLink, msg_id: int, row: Row, home: HomeConfig) -> bytes:
    """The high-rate position and attitude messages, packed without message objects."""
    if msg_id == MSG_LOCAL_POSITION_NED:
        return encode_fields(mav, mavlink2.MAVLink_local_position_ned_message, row.time_boot_ms,
                             *row.pos, *row.vel)
    if msg_id == MSG_ATTITUDE:
        return encode_fields(mav, mavlink2.MAVLink_attitude_message, row.time_boot_ms, row.roll,
                             row.pitch, row.yaw, 0.0, 0.0, row.yaw_rate)
    lat, lon = geodetic(home, row.pos[0], row.pos[1])
    hdg = round(math.degrees(row.yaw) * 100.0) % 36000
    vel_cm = [max(-32768, min(32767, round(v * 100.0))) for v in row.vel]
    return encode_fields(mav, mavlink2.MAVLink_global_position_int_message, row.time_boot_ms,
                         lat, lon, round((home.alt_m - row.pos[2]) * 1000.0),
                         round(-row.pos[2] * 1000.0), *vel_cm, hdg)


class Layout:
    """How a message class's declaration-order fields become its struct's arguments: the
    missing extension fields' zeros, the wire order, arrays flattened.  Derived from the
    class once, so that the bytes are packed without a message object (several times
    faster) from the same description the object is built from."""

    def __init__(self, cls: type[mavlink2.MAVLink_message]) -> None:
        self.cls, self.msg_id, self.crc_extra = cls, cls.id, cls.crc_extra
        self.pack = cls.unpacker.pack
        length = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
        self.zeros = tuple([0] * length[name] if length[name] else 0
                           for name in cls.fieldnames)
        self.order = itemgetter(*(cls.fieldnames.index(name)
                                  for name in cls.ordered_fieldnames))
        # A message without arrays, described in full, is one reorder from its struct.
        self.payload: Callable[[tuple[Any, ...]], bytes] = (
            self._flat if any(cls.array_lengths) else self._plain)

    def full(self, values: tuple[Any, ...]) -> tuple[Any, ...]:
        return values if len(values) == len(self.zeros) else values + self.zeros[len(values):]

    def _plain(self, values: tuple[Any, ...]) -> bytes:
        payload: bytes = self.pack(*self.order(self.full(values)))
        return payload

    def _flat(self, values: tuple[Any, ...]) -> bytes:
        ordered = self.order(self.full(values))
        payload: bytes = self.pack(*(x for v in ordered
                                     for x in (v if isinstance(v, list) else (v,))))
        return payload


HEARTBEAT = Layout(mavlink2.MAVLink_heartbeat_message)
SYS_STATUS = Layout(mavlink2.MAVLink_sys_status_message)
EXTENDED_SYS_STATE = Layout(mavlink2.MAVLink_extended_sys_state_message)
GPS_RAW_INT = Layout(mavlink2.MAVLink_gps_raw_int_message)
VFR_HUD = Layout(mavlink2.MAVLink_vfr_hud_message)
HOME_POSITION = Layout(mavlink2.MAVLink_home_position_message)
BATTERY_STATUS = Layout(mavlink2.MAVLink_battery_status_message)
AUTOPILOT_VERSION = Layout(mavlink2.MAVLink_autopilot_version_message)
Fields = tuple[Layout, tuple[Any, ...]]


def status_fields(msg_id: int, row: Row, home: HomeConfig, flavour: str, mode: str,
                  armed: bool, sysid: int, home_ned_m: tuple[float, float, float],
                  ) -> Fields | None:
    """The one description of the low-rate messages: a message's layout and its fields in
    declaration order (as its `*_encode` takes them; extension fields left off are 0), or
    None for an id this module does not produce."""
    if msg_id == MSG_HEARTBEAT:
        base = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
        return HEARTBEAT, (MAV_TYPE_QUADROTOR, autopilot_of_flavour(flavour), base,
                           encode_custom_mode(flavour, mode),
                           MAV_STATE_ACTIVE if armed else MAV_STATE_STANDBY, 3)
    if msg_id == MSG_SYS_STATUS:
        return SYS_STATUS, (SENSORS_OK, SENSORS_OK, SENSORS_OK, 200, 16200, -1, 100, 0, 0, 0, 0,
                            0, 0, 0, 0, 0)
    if msg_id == MSG_EXTENDED_SYS_STATE:
        return EXTENDED_SYS_STATE, (0, landed_state(row, mode, armed))
    if msg_id == MSG_GPS_RAW_INT:
        lat, lon = geodetic(home, row.pos[0], row.pos[1])
        speed_cm_s = min(65534, round(math.hypot(row.vel[0], row.vel[1]) * 100.0))
        course = round(math.degrees(math.atan2(row.vel[1], row.vel[0])) * 100.0) % 36000
        # 3D fix, HDOP/VDOP 0.8, 12 satellites: what a healthy SITL GPS reports.
        return GPS_RAW_INT, (row.time_boot_ms * 1000, 3, lat, lon,
                             round((home.alt_m - row.pos[2]) * 1000.0), 80, 80, speed_cm_s,
                             course, 12, 0, 0, 0, 0, 0, 0)
    if msg_id == MSG_VFR_HUD:
        speed = math.hypot(row.vel[0], row.vel[1])
        return VFR_HUD, (speed, speed, round(math.degrees(row.yaw)) % 360, 50 if armed else 0,
                         home.alt_m - row.pos[2], -row.vel[2])
    return _rare_fields(msg_id, row, home, flavour, sysid, home_ned_m)


def _rare_fields(msg_id: int, row: Row, home: HomeConfig, flavour: str, sysid: int,
                 home_ned_m: tuple[float, float, float]) -> Fields | None:
    """status_fields of the messages sent once or every few seconds."""
    if msg_id == MSG_HOME_POSITION:
        lat, lon = geodetic(home, home_ned_m[0], home_ned_m[1])
        alt_mm = round((home.alt_m - home_ned_m[2]) * 1000.0)
        return HOME_POSITION, (lat, lon, alt_mm, *home_ned_m, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0,
                               0.0, row.time_boot_ms * 1000)
    if msg_id == MSG_BATTERY_STATUS:
        return BATTERY_STATUS, (0, 1, 1, 32767, [16200] + [65535] * 9, -1, -1, -1, 100)
    if msg_id == MSG_AUTOPILOT_VERSION:
        caps = CAPABILITIES | PARAM_ENCODING[flavour]
        return AUTOPILOT_VERSION, (caps, SW_VERSION[flavour], 0, 0, 0, [0] * 8, [0] * 8,
                                   [0] * 8, 0x26AC, 0x0011, sysid)
    return None


# Produced by status_fields; the first five are streamed at 1-5 Hz.
STATUS_IDS = frozenset({MSG_HEARTBEAT, MSG_SYS_STATUS, MSG_EXTENDED_SYS_STATE, MSG_GPS_RAW_INT,
                        MSG_VFR_HUD, MSG_HOME_POSITION, MSG_BATTERY_STATUS,
                        MSG_AUTOPILOT_VERSION})


def status_message(mav: mavlink2.MAVLink, msg_id: int, row: Row, home: HomeConfig, flavour: str,
                   mode: str, armed: bool, sysid: int,
                   home_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
                   ) -> mavlink2.MAVLink_message | None:
    """status_fields as a message object, or None for an id this module does not produce."""
    got = status_fields(msg_id, row, home, flavour, mode, armed, sysid, home_ned_m)
    if got is None:
        return None
    layout, values = got
    return layout.cls(*layout.full(values))


def status_bytes(mav: mavlink2.MAVLink, msg_id: int, row: Row, home: HomeConfig, flavour: str,
                 mode: str, armed: bool, sysid: int,
                 home_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> bytes | None:
    """status_fields packed as the next frame of `mav` (the bytes `status_message` packs),
    or None for an id this module does not produce."""
    got = status_fields(msg_id, row, home, flavour, mode, armed, sysid, home_ned_m)
    if got is None:
        return None
    layout, values = got
    return encode_payload(mav, layout.msg_id, layout.crc_extra, layout.payload(values))
