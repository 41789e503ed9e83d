"""COMMAND_LONG / COMMAND_INT and setpoints for one simulated vehicle, command by command.

Every command gets exactly one COMMAND_ACK; every result other than ACCEPTED also gets a
STATUSTEXT saying why.  NaN (COMMAND_LONG) and INT32_MAX (COMMAND_INT x/y) mean "unused /
default" wherever MAVLink allows it (SDKs fill every unused field with them); fields whose
value the spec fixes (a message id, ARM_DISARM's 0/1) must be exact or the command is DENIED.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from agents.mavlink.wire import encode
from agents.mavlink.wire_decode import MAVLinkMessage as Msg
from sim_backend import telemetry as tm
from sim_backend.autopilot import ACCEPTED, DENIED, SEVERITY_WARNING, UNSUPPORTED
from sim_backend.endpoint_view import EndpointView, Rx
from sim_backend.setpoint import SetpointRejected, decode_setpoint

MAV_CMD_DO_REPOSITION = 192
MAV_CMD_GET_HOME_POSITION = 410
MAV_CMD_GET_MESSAGE_INTERVAL = 510
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
MAV_CMD_REQUEST_PROTOCOL_VERSION = 519
MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES = 520
INT32_MAX = 2**31 - 1
RELATIVE_ALT_FRAMES = (3, 6)  # GLOBAL_RELATIVE_ALT(_INT)
MSG_MESSAGE_INTERVAL = 244
Params = tuple[float, ...]
# MAV_RESULT, the reply (bytes, or what packs it after the ACK), reason when not ACCEPTED
Outcome = tuple[int, bytes | Callable[[], bytes], str]
CommandHandler = Callable[[EndpointView, Params, Rx], Outcome]


def on_setpoint(ep: EndpointView, msg: Msg, rx: Rx) -> str:
    return apply_setpoint(ep, msg.type_mask, msg.coordinate_frame, (msg.x, msg.y, msg.z),
                          (msg.vx, msg.vy, msg.vz), msg.yaw, msg.yaw_rate, rx)


def apply_setpoint(ep: EndpointView, type_mask: int, frame: int,
                   pos: tuple[float, float, float], vel: tuple[float, float, float],
                   yaw: float, yaw_rate: float, rx: Rx) -> str:
    """SET_POSITION_TARGET_LOCAL_NED's fields to the autopilot; its outcome.  Also straight
    from the wire, without a message object (sim_backend.endpoint, agents.mavlink.fast_rx)."""
    row = rx.row
    try:
        sp = decode_setpoint(type_mask, frame, pos, vel, yaw, yaw_rate, row.pos, row.yaw)
    except SetpointRejected as exc:
        key = "ignored_nonfinite" if "finite" in str(exc) else "ignored_setpoints"
        ep.counters[key] += 1
        return "refused"
    ep.counters["setpoints"] += 1
    ep.autopilot.on_setpoint(sp, rx.now_s, row.landed)
    return "handled"


def command_params(msg: Msg) -> Params:
    """Seven float params; COMMAND_INT x/y become degrees, INT32_MAX there becomes NaN."""
    p = (msg.param1, msg.param2, msg.param3, msg.param4)
    if msg.get_type() == "COMMAND_LONG":
        return (*p, msg.param5, msg.param6, msg.param7)
    x = math.nan if msg.x == INT32_MAX else msg.x * 1e-7
    y = math.nan if msg.y == INT32_MAX else msg.y * 1e-7
    return (*p, x, y, msg.z)


def on_command(ep: EndpointView, msg: Msg, rx: Rx) -> str:
    ep.counters["commands"] += 1
    cmd = msg.command
    params = command_params(msg)
    frame = msg.frame if msg.get_type() == "COMMAND_INT" else 0
    handler = ENDPOINT_COMMANDS.get(cmd)
    if cmd == MAV_CMD_DO_REPOSITION:
        result, reply, why = _reposition(ep, params, frame, rx)
    elif handler is not None:
        result, reply, why = handler(ep, params, rx)
    else:
        ap = ep.autopilot
        result = ap.command(cmd, params, rx.now_s, rx.row.pos, rx.row.landed)
        reply, why = b"", ap.reason
    ack = ep.mav.command_ack_encode(cmd, result, 0, 0, msg.get_srcSystem(),
                                    msg.get_srcComponent())
    out = encode(ep.mav, ack) + (reply() if callable(reply) else reply)
    if result != ACCEPTED:
        ep.counters["commands_not_accepted"] += 1
        out += ep.statustext(SEVERITY_WARNING, why or f"command {cmd}: result {result}")
    ep.send_to(out, rx.addr)
    return "answered"


def exact_id(value: float) -> int | None:
    """A message id given as a float param: a whole number in 0..2**24-1, else None."""
    if not math.isfinite(value) or value != int(value) or not 0 <= value < 2**24:
        return None
    return int(value)


def _request_message(ep: EndpointView, p: Params, rx: Rx) -> Outcome:
    msg_id = exact_id(p[0])
    if msg_id is None:
        return DENIED, b"", f"REQUEST_MESSAGE: param1 {p[0]:g} is not a message id"
    if msg_id == MSG_MESSAGE_INTERVAL:
        wanted = exact_id(p[1])
        if wanted is None:
            return DENIED, b"", "REQUEST_MESSAGE MESSAGE_INTERVAL: param2 is no message id"
        return _get_interval(ep, (float(wanted),), rx)
    reply = ep.packer(msg_id, rx.row)
    if reply is None:
        return DENIED, b"", f"REQUEST_MESSAGE: message {msg_id} not available"
    return ACCEPTED, reply, ""


def _reply_of(msg_id: int) -> CommandHandler:
    def handler(ep: EndpointView, p: Params, rx: Rx) -> Outcome:
        reply = ep.packer(msg_id, rx.row)
        return (ACCEPTED, reply, "") if reply else (UNSUPPORTED, b"", "not available")
    return handler


def _set_interval(ep: EndpointView, p: Params, rx: Rx) -> Outcome:
    msg_id, interval_us = exact_id(p[0]), p[1]
    if msg_id is None or msg_id not in ep.default_intervals:
        return DENIED, b"", f"SET_MESSAGE_INTERVAL: message {p[0]:g} is not streamed"
    if not math.isfinite(interval_us) or not -1 <= interval_us <= INT32_MAX:
        return DENIED, b"", f"SET_MESSAGE_INTERVAL: interval {interval_us:g} us invalid"
    if interval_us == -1:
        ep.intervals[msg_id] = 0.0
    elif interval_us == 0:
        ep.intervals[msg_id] = ep.default_intervals[msg_id]
    else:
        ep.intervals[msg_id] = max(interval_us * 1e-6, 1e-3)
    ep.next_due[msg_id] = rx.now_s
    return ACCEPTED, b"", ""


def _get_interval(ep: EndpointView, p: Params, rx: Rx) -> Outcome:
    msg_id = exact_id(p[0])
    if msg_id is None or msg_id > 0xFFFF:
        return DENIED, b"", f"GET_MESSAGE_INTERVAL: param1 {p[0]:g} is not a message id"
    interval = ep.intervals.get(msg_id)
    # -1: stream off; 0: not produced as a stream.
    us = 0 if interval is None else (-1 if interval <= 0 else min(round(interval * 1e6),
                                                                  INT32_MAX))
    return ACCEPTED, lambda: encode(ep.mav, ep.mav.message_interval_encode(msg_id, us)), ""


def _reposition(ep: EndpointView, p: Params, frame: int, rx: Rx) -> Outcome:
    """DO_REPOSITION: lat/lon (NaN = here), alt (NaN = current; AMSL or relative by frame)."""
    pos = rx.row.pos
    lat, lon, alt = p[4], p[5], p[6]
    if not (math.isnan(lat) or -90.0 <= lat <= 90.0) or \
            not (math.isnan(lon) or -180.0 <= lon <= 180.0) or math.isinf(alt):
        return DENIED, b"", "DO_REPOSITION: position out of range"
    north, east = pos[0], pos[1]
    if not (math.isnan(lat) or math.isnan(lon)):
        north, east = tm.local_of_geodetic(ep.home, lat, lon)
    z = pos[2]
    if not math.isnan(alt):
        z = -alt if frame in RELATIVE_ALT_FRAMES else ep.home.alt_m - alt
    ap = ep.autopilot
    result = ap.reposition((north, east, min(z, 0.0)), rx.row.landed)
    return result, b"", ap.reason


ENDPOINT_COMMANDS: dict[int, CommandHandler] = {
    MAV_CMD_REQUEST_MESSAGE: _request_message,
    MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: _reply_of(tm.MSG_AUTOPILOT_VERSION),
    MAV_CMD_REQUEST_PROTOCOL_VERSION: _reply_of(tm.MSG_PROTOCOL_VERSION),
    MAV_CMD_GET_HOME_POSITION: _reply_of(tm.MSG_HOME_POSITION),
    MAV_CMD_SET_MESSAGE_INTERVAL: _set_interval,
    MAV_CMD_GET_MESSAGE_INTERVAL: _get_interval,
}
