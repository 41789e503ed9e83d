"""MAVLink bytes in: a datagram's frames parsed with struct (the receive half of wire.py).

Frames are parsed with struct and the message types we handle at rate (`FAST_IDS`) are
decoded straight into pymavlink's message classes, falling back to pymavlink's own decoder
for every other type.  Accept/reject decisions and the count of bad fragments equal
pymavlink's parser (robust mode) datagram by datagram (tests/unit/test_mavlink_fastparse.py
pins both).  A UDP datagram carries whole packets, so each is parsed on its own; bytes a
datagram leaves unparsed can never corrupt the next one.  A well-framed frame of a type
the dialect lacks cannot be CRC-checked (its CRC extra is unknown): it is dropped and
counted apart from bad bytes (`unknown`), as pymavlink's parser tells UNKNOWN from
BAD_DATA, so that the rest of a real autopilot's stream does not look like garbage.
"""

from __future__ import annotations

import re
import struct
import sys
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType
from typing import Any, TypeAlias

# A message, or a codec, of whichever dialect module made it.  pymavlink ships no types,
# so mypy would see any of its classes as Any anyway.
MAVLinkMessage: TypeAlias = Any
Codec: TypeAlias = Any
STX_V2, STX_V1 = 0xFD, 0xFE
_MARKER = re.compile(b"[\xfd\xfe]")
_HEADER_V2 = struct.Struct("<BBBBBBBHB")
_HEADER_V1 = struct.Struct("<BBBBBB")
# Types decoded without pymavlink's parser: what flows at the control rate, and the
# status and command traffic around it.  Each has scalar fields only (no arrays, no text).
FAST_IDS = (0, 1, 2, 24, 30, 32, 33, 74, 75, 76, 77, 84, 111, 245)


@dataclass(frozen=True)
class Decoded:
    """Good messages of one datagram, how many bad fragments it held, and how many
    well-framed frames of types the codec's dialect lacks (unchecked, dropped)."""

    messages: tuple[MAVLinkMessage, ...]
    bad: int
    unknown: int = 0


class _FastType:
    """How one message type is decoded: its struct, fields in wire order, fixed attributes."""

    __slots__ = ("cls", "extra", "fixed", "names", "size", "unpack")

    def __init__(self, cls: type[MAVLinkMessage]) -> None:
        self.cls = cls
        self.size = cls.unpacker.size
        self.unpack = cls.unpacker.unpack
        self.names = tuple(cls.ordered_fieldnames)
        self.extra = bytes((cls.crc_extra,))
        values = self.unpack(bytes(self.size))
        proto = cls(*(values[i] for i in cls.orders))
        # What the constructor sets besides the fields and the per-frame header.
        self.fixed = {k: v for k, v in vars(proto).items()
                      if k.startswith("_") and k not in _PER_FRAME}


_PER_FRAME = frozenset({"_header", "_msgbuf", "_payload", "_crc", "_signed", "_link_id"})


@dataclass(frozen=True, slots=True)
class _Dialect:
    """What decoding and framing need of one dialect module: built once per module."""

    fast: dict[int, _FastType]
    known: frozenset[int]
    header: type
    crc: Callable[[bytes | memoryview, int], int]
    error: type[Exception]

    @classmethod
    def of(cls, module: ModuleType) -> _Dialect:
        types = module.mavlink_map
        return cls({i: _FastType(types[i]) for i in FAST_IDS if i in types}, frozenset(types),
                   module.MAVLink_header, module.mcrf4xx, module.MAVError)


_DIALECTS: dict[type, _Dialect] = {}  # by the dialect's codec class
_UNKNOWN: Any = object()  # _decode_frame's verdict on a type the dialect lacks


def dialect_tables(mav: Codec) -> _Dialect:
    """The tables of the dialect `mav` belongs to (any generated module's MAVLink)."""
    codec_cls = type(mav)
    tables = _DIALECTS.get(codec_cls)
    if tables is None:
        tables = _DIALECTS[codec_cls] = _Dialect.of(sys.modules[codec_cls.__module__])
    return tables


def decode_datagram(mav: Codec, data: bytes) -> Decoded:
    """Parse one datagram; garbage, CRC errors and truncation become a `bad` count, whole
    frames of types `mav`'s dialect lacks an `unknown` one.

    Framing follows pymavlink's robust parser: a run of bytes that starts no frame is one
    bad fragment, and so is an incomplete frame at the end.  `mav` decodes the types not
    in FAST_IDS (all of them, if it checks signatures itself)."""
    if type(data) is not bytes:  # a bytearray or memoryview: frames are sliced as bytes
        data = bytes(data)
    tables = _DIALECTS.get(type(mav)) or dialect_tables(mav)  # inline: this runs per datagram
    keyed = mav.signing.secret_key is not None
    good: list[MAVLinkMessage] = []
    bad, unknown, i, n = 0, 0, 0, len(data)
    while i < n:
        stx = data[i]
        if stx != STX_V2 and stx != STX_V1:
            bad += 1
            found = _MARKER.search(data, i + 1)
            i = n if found is None else found.start()
            continue
        if n - i < 3:
            bad += 1
            break
        flags = data[i + 2] if stx == STX_V2 else 0
        end = i + data[i + 1] + (8 if stx == STX_V1 else 25 if flags & 1 else 12)
        if end > n:
            bad += 1
            break
        frame, i = data[i:end], end
        try:
            msg = None if flags & 0xFE else _decode_frame(mav, tables, frame, keyed)
        except tables.error:
            msg = None
        except Exception:  # pymavlink raises assorted errors on hostile input; drop it all
            return Decoded((), 1)
        if msg is None:
            bad += 1
        elif msg is _UNKNOWN:
            unknown += 1
        else:
            good.append(msg)
    return Decoded(tuple(good), bad, unknown)


def _decode_frame(mav: Codec, tables: _Dialect, frame: bytes, keyed: bool,
                  ) -> MAVLinkMessage | None:
    """One whole frame as a message; None when it is bad (CRC), _UNKNOWN when its type
    is not in the dialect."""
    if frame[0] == STX_V2:
        _, mlen, flags, compat, seq, sysid, compid, low, high = _HEADER_V2.unpack_from(frame)
        msg_id, start = low | high << 16, 10
    else:
        _, mlen, seq, sysid, compid, msg_id = _HEADER_V1.unpack_from(frame)
        flags = compat = 0
        start = 6
    fast = tables.fast.get(msg_id)
    if fast is None or keyed:
        if msg_id not in tables.known:
            return _UNKNOWN
        return mav.decode(bytearray(frame))
    crc_at = start + mlen
    crc = frame[crc_at] | frame[crc_at + 1] << 8
    if tables.crc(frame[1:crc_at] + fast.extra, 0xFFFF) != crc:
        return None
    payload = frame[start:crc_at]
    if mlen != fast.size:  # MAVLink 2 drops trailing zeros; longer payloads are cut
        payload = payload[:fast.size].ljust(fast.size, b"\0")
    msg: MAVLinkMessage = object.__new__(fast.cls)
    fields = dict(fast.fixed)
    fields.update(zip(fast.names, fast.unpack(payload), strict=True))
    fields["_header"] = tables.header(msg_id, flags, compat, mlen, seq, sysid, compid)
    fields["_msgbuf"], fields["_payload"], fields["_crc"] = frame, frame[6:crc_at], crc
    fields["_signed"], fields["_link_id"] = False, None
    msg.__dict__ = fields
    return msg


