"""A pymavlink ground station does QGroundControl's connect-time sequence, then flies an RTL."""

from __future__ import annotations

import math
import struct

import pytest

from tests.integration.sim_process import PlainClient, assert_all_answered, start_sim

pytestmark = [pytest.mark.integration, pytest.mark.timeout(90)]
NAN = math.nan
MISSION_INT, PARAM_BYTEWISE = 4, 16


def command_nan(c: PlainClient, cmd: int, *params: float) -> int:
    """COMMAND_LONG with NaN in every param not given, as SDKs and QGC send them."""
    p = list(params) + [NAN] * (7 - len(params))
    c.acks.clear()
    c.send(c.mav.command_long_encode(c.sysid, 1, cmd, 0, *p))
    c.until(lambda: any(k == cmd for k, _ in c.acks), 2.0, f"ACK of {cmd}")
    return next(r for k, r in c.acks if k == cmd)


def connect_sequence(c: PlainClient) -> None:
    c.until(lambda: "HEARTBEAT" in c.last, 10.0, "vehicle heartbeat")
    c.send(c.mav.heartbeat_encode(6, 8, 0, 0, 4))  # GCS, MAV_AUTOPILOT_INVALID
    assert command_nan(c, 512, 148) == 0
    c.until(lambda: "AUTOPILOT_VERSION" in c.last, 2.0, "AUTOPILOT_VERSION")
    caps = c.last["AUTOPILOT_VERSION"].capabilities  # type: ignore[attr-defined]
    assert caps & MISSION_INT and caps & PARAM_BYTEWISE
    assert command_nan(c, 512, 300) == 0  # PROTOCOL_VERSION (not in pymavlink's dialect)
    # Parameters: every index once, typed; PX4's integers travel bytewise.
    c.history.clear()
    params: dict[str, object] = {}

    def all_params() -> bool:
        params.update((m.param_id, m) for m in c.history  # type: ignore[attr-defined]
                      if m.get_type() == "PARAM_VALUE")  # type: ignore[attr-defined]
        counts = {m.param_count for m in params.values()}  # type: ignore[attr-defined]
        return len(counts) == 1 and len(params) == counts.pop()

    c.send(c.mav.param_request_list_encode(1, 1))
    c.until(all_params, 3.0, "all parameters")
    sysid = params["MAV_SYS_ID"]
    assert sysid.param_type == 6  # type: ignore[attr-defined]
    assert struct.unpack("<i", struct.pack("<f", sysid.param_value))[0] == 1  # type: ignore
    for mission_type in (0, 1, 2):  # mission, fence, rally: all empty
        c.send(c.mav.mission_request_list_encode(1, 1, mission_type))
        c.until(lambda mt=mission_type: "MISSION_COUNT" in c.last and
                c.last["MISSION_COUNT"].mission_type == mt, 2.0, "MISSION_COUNT")
        assert c.last.pop("MISSION_COUNT").count == 0  # type: ignore[attr-defined]
        c.send(c.mav.mission_ack_encode(1, 1, 0, mission_type))
    # MAVFTP (component metadata): an immediate NAK, so QGC falls back at once.
    open_ro = struct.pack("<HBBBBBBI", 1, 0, 4, 21, 0, 0, 0, 0) + b"@PARAM/param.pck\x00"
    c.send(c.mav.file_transfer_protocol_encode(0, 1, 1, list(open_ro.ljust(251, b"\0"))))
    c.until(lambda: "FILE_TRANSFER_PROTOCOL" in c.last, 2.0, "MAVFTP NAK")
    assert c.last["FILE_TRANSFER_PROTOCOL"].payload[3] == 129  # type: ignore[attr-defined]
    assert command_nan(c, 410) == 0  # GET_HOME_POSITION
    c.until(lambda: "HOME_POSITION" in c.last, 2.0, "HOME_POSITION")
    assert command_nan(c, 511, 24, 100_000) == 0  # GPS_RAW_INT at 10 Hz
    assert command_nan(c, 510, 24) == 0
    c.until(lambda: "MESSAGE_INTERVAL" in c.last, 2.0, "MESSAGE_INTERVAL")
    assert c.last["MESSAGE_INTERVAL"].interval_us == 100_000  # type: ignore[attr-defined]
    c.send(c.mav.ping_encode(123456, 7, 0, 0))
    c.until(lambda: "PING" in c.last, 2.0, "PING reply")


def mission_round_trip(c: PlainClient) -> None:
    c.send(c.mav.mission_count_encode(1, 1, 2, 0))
    for seq in (0, 1):
        c.until(lambda s=seq: "MISSION_REQUEST_INT" in c.last and
                c.last["MISSION_REQUEST_INT"].seq == s, 2.0, f"request of item {seq}")
        c.send(c.mav.mission_item_int_encode(1, 1, seq, 6, 16, 0, 1, 0, 0, 0, NAN,
                                             473977420 + seq * 1000, 85455940, 10.0, 0))
    c.until(lambda: "MISSION_ACK" in c.last, 2.0, "MISSION_ACK")
    assert c.last.pop("MISSION_ACK").type == 0  # type: ignore[attr-defined]
    c.send(c.mav.mission_request_list_encode(1, 1, 0))
    c.until(lambda: "MISSION_COUNT" in c.last, 2.0, "MISSION_COUNT")
    assert c.last["MISSION_COUNT"].count == 2  # type: ignore[attr-defined]
    c.send(c.mav.mission_request_int_encode(1, 1, 1, 0))
    c.until(lambda: "MISSION_ITEM_INT" in c.last, 2.0, "MISSION_ITEM_INT")
    assert c.last["MISSION_ITEM_INT"].x == 473978420  # type: ignore[attr-defined]
    c.send(c.mav.mission_clear_all_encode(1, 1, 0))
    c.until(lambda: "MISSION_ACK" in c.last, 2.0, "clear ACK")


def test_qgc_connect_sequence_then_takeoff_rtl_and_auto_disarm() -> None:
    sim = start_sim()
    c = PlainClient(sim.send_base, sim.listen_base)
    try:
        connect_sequence(c)
        mission_round_trip(c)
        c.send(c.mav.param_set_encode(1, 1, b"RTL_RETURN_ALT", 4.0, 9))
        c.send(c.mav.set_mode_encode(1, 1, (4 << 16) | (3 << 24)))  # SET_MODE HOLD: acked
        c.until(lambda: (176, 0) in c.acks, 2.0, "SET_MODE ACK")
        assert command_nan(c, 400, 1) == 0  # arm, NaN elsewhere
        assert command_nan(c, 22) == 0  # takeoff to MIS_TAKEOFF_ALT
        c.until(lambda: c.last["LOCAL_POSITION_NED"].z < -2.3, 10.0, "take-off")  # type: ignore
        assert command_nan(c, 192, -1, 1, 0, NAN, 47.3978, 8.545594, NAN) == 0  # 6 m north
        c.until(lambda: c.last["LOCAL_POSITION_NED"].x > 5.0, 10.0, "reposition")  # type: ignore
        assert command_nan(c, 20) == 0  # NAV_RETURN_TO_LAUNCH
        c.until(lambda: not c.last["HEARTBEAT"].base_mode & 128, 30.0,  # type: ignore
                "RTL: return, land and disarm")
        pos = c.last["LOCAL_POSITION_NED"]
        assert math.hypot(pos.x, pos.y) < 0.5 and pos.z > -0.05  # type: ignore[attr-defined]
    finally:
        c.close()
        code = sim.stop()
    assert code == 0
    outcomes = assert_all_answered(sim.output())
    assert outcomes["FILE_TRANSFER_PROTOCOL:answered"] == 1 and outcomes["PING:answered"] == 1
