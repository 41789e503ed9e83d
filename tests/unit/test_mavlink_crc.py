"""MAVLink's CRC-16/MCRF4XX from binascii (agents.mavlink.crc) against fastcrc's, which
pymavlink uses, and against the checksum a real frame carries."""

from __future__ import annotations

import fastcrc
import pytest
from hypothesis import given
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common

from agents.mavlink import lean_common
from agents.mavlink.crc import mcrf4xx


@given(st.binary(max_size=300), st.integers(0, 0xFFFF))
def test_the_crc_is_fastcrcs_for_any_bytes_and_start(data: bytes, start: int) -> None:
    assert mcrf4xx(data, start) == fastcrc.crc16.mcrf4xx(data, start)


@given(st.lists(st.binary(max_size=40), max_size=5))
def test_the_crc_goes_on_across_pieces(pieces: list[bytes]) -> None:
    crc = 0xFFFF
    for piece in pieces:
        crc = mcrf4xx(piece, crc)
    assert crc == mcrf4xx(b"".join(pieces))


def test_a_frame_packed_by_pymavlink_checks_with_the_lean_dialect() -> None:
    mav = common.MAVLink(None, srcSystem=3, srcComponent=1)
    frame = common.MAVLink_heartbeat_message(2, 12, 0, 0, 4, 3).pack(mav)
    body, crc = frame[1:-2], int.from_bytes(frame[-2:], "little")
    assert mcrf4xx(body + bytes((common.MAVLink_heartbeat_message.crc_extra,))) == crc
    parsed = lean_common.MAVLink(None).parse_char(frame)
    assert parsed is not None and parsed.get_type() == "HEARTBEAT"
    damaged = frame[:-1] + bytes((frame[-1] ^ 1,))
    with pytest.raises(lean_common.MAVError, match="CRC"):
        lean_common.MAVLink(None).parse_char(damaged)
