"""Build MAVLink 2 frames with arbitrary payload bytes (valid CRC), for property and fuzz tests."""

from __future__ import annotations

import re
import socket
import struct
from typing import Any

from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2
from pymavlink.dialects.v20.common import mcrf4xx

from agents.mavlink.signing import signature
from agents.mavlink.wire import new_codec
from agents.mavlink.wire_decode import MAVLinkMessage, decode_datagram
from sim_backend.endpoint import HANDLERS, IGNORED

HEADER = struct.Struct("<BBBBBBBHB")


def message_class(kind: str) -> type[mavlink2.MAVLink_message]:
    return next(c for c in mavlink2.mavlink_map.values() if c.msgname == kind)


# Every message type the simulator handles or ignores by design.
HANDLED_TYPES = tuple(sorted(set(HANDLERS) | IGNORED))
HANDLED_CLASSES = tuple(message_class(k) for k in HANDLED_TYPES)


def payload_size(cls: type[mavlink2.MAVLink_message]) -> int:
    return int(cls.unpacker.size)


def raw_frame(cls: type[mavlink2.MAVLink_message], payload: bytes, seq: int = 0,
              sysid: int = 255, compid: int = 190) -> bytes:
    """One MAVLink 2 packet of `cls` carrying `payload` (any bytes) with a correct CRC."""
    payload = payload[:payload_size(cls)]
    msg_id = cls.id
    head = HEADER.pack(0xFD, len(payload), 0, 0, seq & 0xFF, sysid, compid, msg_id & 0xFFFF,
                       msg_id >> 16)
    body = head + payload
    crc = mcrf4xx(body[1:] + bytes((cls.crc_extra,)), 0xFFFF)
    return body + crc.to_bytes(2, "little")


def signed_frame(cls: Any, payload: bytes, sysid: int, compid: int, stamp: int | None,
                 key: bytes, link: int = 0, flags: int = 0) -> bytes:
    """A MAVLink 2 frame of `cls` around `payload` (any bytes), signed with `key` at `stamp`
    (unsigned when None), with a good CRC; `flags`: more incompatibility flags."""
    body = HEADER.pack(0xFD, len(payload), flags | (stamp is not None), 0, 7, sysid, compid,
                       cls.id & 0xFFFF, cls.id >> 16) + payload
    frame = body + mcrf4xx(body[1:] + bytes((cls.crc_extra,)), 0xFFFF).to_bytes(2, "little")
    if stamp is None:
        return frame
    frame += bytes((link,)) + stamp.to_bytes(6, "little")
    return frame + signature(key, frame)


def damaged(draw: st.DrawFn, data: bytes) -> bytes:
    """`data` as it came, mostly; now and then cut short, or with garbage after it."""
    cut = draw(st.sampled_from((None,) * 6 + ("cut", "garbage")))
    if cut == "cut":
        return data[:draw(st.integers(1, len(data)))]
    if cut == "garbage":
        return data + draw(st.binary(min_size=1, max_size=20))
    return data


def target_offset(cls: type) -> int | None:
    """Byte offset of target_system in the payload (fields in wire order), or None."""
    names = list(cls.ordered_fieldnames)
    if "target_system" not in names:
        return None
    codes = re.findall(r"(\d*)([a-zA-Z?])", cls.unpacker.format.lstrip("<"))
    sizes = [struct.calcsize("<" + n + c) for n, c in codes]
    return sum(sizes[:names.index("target_system")])


def queued_datagrams(client: socket.socket) -> list[list[MAVLinkMessage]]:
    """The messages of every datagram queued on a non-blocking socket, one list each."""
    out = []
    while True:
        try:
            data, _ = client.recvfrom(65535)
        except BlockingIOError:
            return out
        out.append(list(decode_datagram(new_codec(250, 0), data).messages))
