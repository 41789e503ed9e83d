"""MAVLink 2 encoding and per-datagram decoding with pymavlink's generated dialect.

No mavutil: it keeps process-wide state.  A UDP datagram carries whole packets,
so the parser is reset before each one; bytes a datagram leaves unparsed can
then never corrupt the next datagram.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink2
from pymavlink.dialects.v20.common import MAVLink_message as MAVLinkMessage


def new_codec(sysid: int, compid: int) -> mavlink2.MAVLink:
    """An encoder/decoder that sends MAVLink 2 as (sysid, compid) and never raises on input."""
    mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.robust_parsing = True
    return mav


@dataclass(frozen=True)
class Decoded:
    """Good messages of one datagram and how many bad fragments it held."""

    messages: tuple[MAVLinkMessage, ...]
    bad: int


def decode_datagram(mav: mavlink2.MAVLink, data: bytes) -> Decoded:
    """Parse one datagram; garbage, CRC errors and truncation become a `bad` count."""
    mav.buf = bytearray()
    mav.buf_index = 0
    mav.expected_length = mavlink2.HEADER_LEN_V1 + 2
    mav.have_prefix_error = False
    try:
        parsed = mav.parse_buffer(data) or []
    except Exception:  # pymavlink raises assorted errors on hostile input; drop the datagram
        return Decoded((), 1)
    good: list[MAVLinkMessage] = []
    bad = 0
    for msg in parsed:
        if msg.get_type() == "BAD_DATA" or msg.get_type().startswith("UNKNOWN"):
            bad += 1
        else:
            good.append(msg)
    if mav.buf_len() > 0:
        bad += 1
    return Decoded(tuple(good), bad)
