"""The protocols a ground station runs on connect: modes, parameters, missions, MAVFTP, PING.

Handlers take (endpoint, message, rx) and return the outcome the endpoint counts
(sim_backend.endpoint_view).
Missions are stored, listed and cleared as PX4 does, but not flown (MISSION mode is refused).
MAVFTP is not offered: every request gets a NAK at once, so clients fall back to the
parameter and mission protocols instead of waiting for their FTP timeout.
"""

from __future__ import annotations

import math
import struct

from agents.mavlink.modes import MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PX4, decode_custom_mode
from agents.mavlink.wire import encode
from agents.mavlink.wire_decode import MAVLinkMessage as Msg
from sim_backend.autopilot import ACCEPTED, DENIED, SEVERITY_WARNING
from sim_backend.endpoint_view import EndpointView, Handler, Rx

MAV_CMD_DO_SET_MODE = 176
MSG_SET_MODE = 11
MISSION_ACCEPTED, MISSION_ERROR, MISSION_UNSUPPORTED, MISSION_NO_SPACE = 0, 1, 3, 4
MISSION_INVALID_SEQUENCE = 13
MAX_MISSION_ITEMS = 500
FTP_ACK, FTP_NAK = 128, 129
FTP_TERMINATE, FTP_RESET = 1, 2
FTP_PATH_OPS = frozenset({3, 4, 6, 7, 8, 9, 10, 11, 13, 14, 15})
FTP_ERR_UNKNOWN_COMMAND, FTP_ERR_FILE_NOT_FOUND = 7, 10
def _reply(ep: EndpointView, rx: Rx, *msgs: Msg) -> str:
    ep.send_to(b"".join(encode(ep.mav, m) for m in msgs), rx.addr)
    return "answered"


def _refuse(ep: EndpointView, rx: Rx, why: str, *msgs: Msg) -> str:
    ep.counters["refused_messages"] += 1
    _reply(ep, rx, *msgs)
    ep.send_to(ep.statustext(SEVERITY_WARNING, why), rx.addr)
    return "refused"


# ---- modes ------------------------------------------------------------------------------
def on_set_mode(ep: EndpointView, msg: Msg, rx: Rx) -> str:
    """SET_MODE, acknowledged as each autopilot does (PX4 as DO_SET_MODE, ArduPilot as 11)."""
    ap = ep.autopilot
    if msg.base_mode & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        name = decode_custom_mode(ap.flavour, msg.custom_mode)
        result = ap.set_mode(name, rx.now_s, rx.row.pos, rx.row.landed)
    else:
        result, ap.reason = DENIED, "SET_MODE without a custom mode is not supported"
    command = MAV_CMD_DO_SET_MODE if ap.flavour == PX4 else MSG_SET_MODE
    ack = ep.mav.command_ack_encode(command, result, 0, 0, msg.get_srcSystem(),
                                    msg.get_srcComponent())
    if result != ACCEPTED:
        return _refuse(ep, rx, ap.reason, ack)
    return _reply(ep, rx, ack)


# ---- parameters -------------------------------------------------------------------------
def on_param(ep: EndpointView, msg: Msg, rx: Rx) -> str:
    kind = msg.get_type()
    store = ep.params
    if kind == "PARAM_REQUEST_LIST":
        names = [store.name_at(k) for k in range(len(store))]
    elif kind == "PARAM_REQUEST_READ":
        by_index = store.name_at(msg.param_index) if msg.param_index >= 0 else None
        names = [by_index or (msg.param_id if store.index_of(msg.param_id) >= 0 else None)]
    else:
        ok = store.set_from_wire(msg.param_id, msg.param_value, msg.param_type)
        names = [msg.param_id if ok else None]
        apply_params(ep)
    if names == [None]:
        ep.counters["ignored_params"] += 1
        name = msg.param_id if kind == "PARAM_SET" or msg.param_index < 0 else msg.param_index
        return _refuse(ep, rx, f"{kind}: unknown parameter or bad value {name}")
    out = []
    for name in names:
        if name is not None:
            value, ptype = store.wire(name)
            out.append(ep.mav.param_value_encode(name.encode(), value, ptype, len(store),
                                                 store.index_of(name)))
    return _reply(ep, rx, *out)


def apply_params(ep: EndpointView) -> None:
    """Copy the parameters the autopilot obeys into it (at start and after PARAM_SET)."""
    ap, store = ep.autopilot, ep.params
    scale = {"COM_OF_LOSS_T": 1.0, "GUID_TIMEOUT": 1.0, "MIS_TAKEOFF_ALT": 1.0,
             "RTL_RETURN_ALT": 1.0, "RTL_ALT": 0.01, "COM_DISARM_PRFLT": 1.0,
             "COM_DISARM_LAND": 1.0, "DISARM_DELAY": 1.0}
    attr = {"COM_OF_LOSS_T": "setpoint_timeout_s", "GUID_TIMEOUT": "setpoint_timeout_s",
            "MIS_TAKEOFF_ALT": "default_takeoff_alt_m", "RTL_RETURN_ALT": "rtl_alt_m",
            "RTL_ALT": "rtl_alt_m", "COM_DISARM_PRFLT": "disarm_preflight_s",
            "COM_DISARM_LAND": "disarm_land_s", "DISARM_DELAY": "disarm_preflight_s"}
    for name, target in attr.items():
        if store.index_of(name) >= 0:
            value = store.get(name) * scale[name]
            # A disarm delay of 0 or less disables auto-disarm (PX4 and ArduPilot alike).
            if target.startswith("disarm") and value <= 0:
                value = math.inf
            setattr(ap, target, value)


# ---- missions ---------------------------------------------------------------------------
def _mission_ack(ep: EndpointView, msg: Msg, result: int) -> Msg:
    return ep.mav.mission_ack_encode(msg.get_srcSystem(), msg.get_srcComponent(), result,
                                     getattr(msg, "mission_type", 0))


def on_mission(ep: EndpointView, msg: Msg, rx: Rx) -> str:
    kind = msg.get_type()
    if kind == "MISSION_ACK":
        return "handled"  # the end of a download: nothing to answer
    if kind in ("MISSION_REQUEST_PARTIAL_LIST", "MISSION_WRITE_PARTIAL_LIST"):
        return _refuse(ep, rx, "partial mission lists not supported",
                       _mission_ack(ep, msg, MISSION_UNSUPPORTED))
    store = ep.missions
    mission_type = getattr(msg, "mission_type", 0)
    if kind == "MISSION_REQUEST_LIST":
        count = len(store.items) if mission_type == 0 else 0
        return _reply(ep, rx, ep.mav.mission_count_encode(
            msg.get_srcSystem(), msg.get_srcComponent(), count, mission_type))
    if kind == "MISSION_CLEAR_ALL":
        if mission_type in (0, 255):
            store.items, store.upload = [], None
        return _reply(ep, rx, _mission_ack(ep, msg, MISSION_ACCEPTED))
    if kind == "MISSION_SET_CURRENT":
        if msg.seq >= len(store.items):
            return _refuse(ep, rx, f"MISSION_SET_CURRENT: no item {msg.seq}")
        return _reply(ep, rx, ep.mav.mission_current_encode(msg.seq))
    if mission_type != 0:
        return _refuse(ep, rx, "only plain missions are stored (no fence, no rally)",
                       _mission_ack(ep, msg, MISSION_UNSUPPORTED))
    if kind == "MISSION_COUNT":
        return _mission_count(ep, msg, rx)
    if kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
        return _mission_item(ep, msg, rx)
    return _mission_request(ep, msg, rx)


def _request_item(ep: EndpointView, msg: Msg, seq: int) -> Msg:
    return ep.mav.mission_request_int_encode(msg.get_srcSystem(), msg.get_srcComponent(), seq, 0)


def _mission_count(ep: EndpointView, msg: Msg, rx: Rx) -> str:
    store = ep.missions
    if msg.count > MAX_MISSION_ITEMS:
        return _refuse(ep, rx, f"mission too long ({msg.count} > {MAX_MISSION_ITEMS})",
                       _mission_ack(ep, msg, MISSION_NO_SPACE))
    if msg.count == 0:
        store.items, store.upload = [], None
        return _reply(ep, rx, _mission_ack(ep, msg, MISSION_ACCEPTED))
    store.upload, store.upload_count = [], msg.count
    return _reply(ep, rx, _request_item(ep, msg, 0))


def _mission_item(ep: EndpointView, msg: Msg, rx: Rx) -> str:
    store = ep.missions
    if store.upload is None:
        return _refuse(ep, rx, "mission item without an upload in progress",
                       _mission_ack(ep, msg, MISSION_ERROR))
    expected = len(store.upload)
    if msg.seq != expected:
        return _reply(ep, rx, _request_item(ep, msg, expected))  # ask again for the one we need
    x, y = msg.x, msg.y
    if msg.get_type() == "MISSION_ITEM":  # float degrees; a non-finite one is stored as 0
        x, y = (round(v * 1e7) if math.isfinite(v) and abs(v) < 214 else 0 for v in (x, y))
    store.upload.append((msg.frame, msg.command, msg.current, msg.autocontinue, msg.param1,
                         msg.param2, msg.param3, msg.param4, x, y, msg.z))
    if len(store.upload) < store.upload_count:
        return _reply(ep, rx, _request_item(ep, msg, len(store.upload)))
    store.items, store.upload = store.upload, None
    return _reply(ep, rx, _mission_ack(ep, msg, MISSION_ACCEPTED))


def _mission_request(ep: EndpointView, msg: Msg, rx: Rx) -> str:
    items = ep.missions.items
    if msg.seq >= len(items):
        return _refuse(ep, rx, f"no mission item {msg.seq}",
                       _mission_ack(ep, msg, MISSION_INVALID_SEQUENCE))
    item = ep.mav.mission_item_int_encode(msg.get_srcSystem(), msg.get_srcComponent(), msg.seq,
                                          *items[msg.seq], 0)
    return _reply(ep, rx, item)


# ---- MAVFTP, PING, stream requests ------------------------------------------------------
def on_ftp(ep: EndpointView, msg: Msg, rx: Rx) -> str:
    """Answer every MAVFTP request at once: ACK session resets, NAK everything else."""
    payload = bytes(msg.payload)
    seq, session, opcode = struct.unpack_from("<HBB", payload)
    if opcode in (FTP_TERMINATE, FTP_RESET):
        reply_op, data = FTP_ACK, b""
    else:
        error = FTP_ERR_FILE_NOT_FOUND if opcode in FTP_PATH_OPS else FTP_ERR_UNKNOWN_COMMAND
        reply_op, data = FTP_NAK, bytes((error,))
    head = struct.pack("<HBBBBBBI", (seq + 1) & 0xFFFF, session, reply_op, len(data), opcode,
                       0, 0, 0)
    body = (head + data).ljust(251, b"\x00")
    return _reply(ep, rx, ep.mav.file_transfer_protocol_encode(
        0, msg.get_srcSystem(), msg.get_srcComponent(), list(body)))


def on_ping(ep: EndpointView, msg: Msg, rx: Rx) -> str:
    if msg.target_system != 0:
        return "handled"  # a response to a ping of ours (we send none) or someone else's
    return _reply(ep, rx, ep.mav.ping_encode(msg.time_usec, msg.seq, msg.get_srcSystem(),
                                             msg.get_srcComponent()))


def on_request_data_stream(ep: EndpointView, msg: Msg, rx: Rx) -> str:
    # ArduPilot's old stream request: every stream is already on, and it has no reply.
    return "handled"


HANDLERS: dict[str, Handler] = {
    "SET_MODE": on_set_mode,
    "PARAM_REQUEST_LIST": on_param,
    "PARAM_REQUEST_READ": on_param,
    "PARAM_SET": on_param,
    "FILE_TRANSFER_PROTOCOL": on_ftp,
    "PING": on_ping,
    "REQUEST_DATA_STREAM": on_request_data_stream,
    **{kind: on_mission for kind in (
        "MISSION_REQUEST_LIST", "MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM",
        "MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_CLEAR_ALL", "MISSION_ACK",
        "MISSION_SET_CURRENT", "MISSION_REQUEST_PARTIAL_LIST", "MISSION_WRITE_PARTIAL_LIST")},
}
