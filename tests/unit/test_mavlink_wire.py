"""Packing: the fast path equals pymavlink's, sequence numbers advance, garbage is counted."""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink2

from agents.mavlink.wire import encode, encode_fields, new_codec
from agents.mavlink.wire_decode import decode_datagram

CASES = [
    (mavlink2.MAVLink_local_position_ned_message, (1234, 1.0, 2.0, 3.0, 0.1, 0.2, 0.0)),
    (mavlink2.MAVLink_attitude_message, (5, 0.1, -0.2, 0.3, 0.0, 0.0, 0.0)),
    (mavlink2.MAVLink_global_position_int_message, (7, 473977420, 85455940, 488000, 0, 1, -2,
                                                    0, 0)),
    # The simulator's clock service (sim_backend/clock_services.py): int64 ns, a request's tc1 = 0.
    (mavlink2.MAVLink_timesync_message, (52_200_123_456_789, 1_795_561_625_000_000_000)),
    (mavlink2.MAVLink_timesync_message, (0, 52_200_123_456_789)),
    (mavlink2.MAVLink_system_time_message, (1_795_561_625_123_456, 4_294_967_295)),
]


def test_fast_pack_equals_pymavlink_and_decodes() -> None:
    for cls, fields in CASES:
        a, b = new_codec(3, 1), new_codec(3, 1)
        for _ in range(3):
            assert encode_fields(b, cls, *fields) == encode(a, cls(*fields))
        msgs = decode_datagram(new_codec(9, 0), encode_fields(b, cls, *fields)).messages
        assert len(msgs) == 1 and msgs[0].get_srcSystem() == 3 and msgs[0].get_seq() == 3


def test_sequence_wraps() -> None:
    mav = new_codec(1, 1)
    mav.seq = 255
    encode(mav, mavlink2.MAVLink_heartbeat_message(2, 12, 1, 0, 3, 3))
    assert mav.seq == 0


def test_garbage_truncation_and_bad_crc_counted() -> None:
    mav, rx = new_codec(1, 1), new_codec(2, 1)
    good = encode(mav, mavlink2.MAVLink_heartbeat_message(2, 12, 1, 0, 3, 3))
    assert decode_datagram(rx, b"\x01\x02garbage").bad >= 1
    assert decode_datagram(rx, good[:-3]).bad == 1
    assert decode_datagram(rx, good[:-1] + bytes([good[-1] ^ 0xFF])).bad == 1
    both = decode_datagram(rx, good + good)
    assert len(both.messages) == 2 and both.bad == 0


def test_struct_packed_status_messages_equal_pymavlink_objects() -> None:
    """The simulator's 1-5 Hz streams packed by struct are the bytes pymavlink packs."""
    from agents.scenario.model import HomeConfig
    from sim_backend import telemetry as tm

    home = HomeConfig()
    row = tm.Row(123456, (3.5, -7.25, -10.0), (1.5, -0.5, 0.25), 0.1, -0.2, 2.5, 0.3, False)
    for msg_id in sorted(tm.STATUS_IDS):
        for flavour, mode, armed in (("px4", "OFFBOARD", True), ("ardupilot", "LAND", False)):
            a, b = new_codec(7, 1), new_codec(7, 1)
            a.seq = b.seq = 200
            obj = tm.status_message(a, msg_id, row, home, flavour, mode, armed, 7, (1.0, 2.0, 0))
            assert obj is not None
            packed = tm.status_bytes(b, msg_id, row, home, flavour, mode, armed, 7, (1.0, 2.0, 0))
            assert packed == encode(a, obj), obj.get_type()
