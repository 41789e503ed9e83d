"""MAVLink bytes in and out: the one place that makes and reads them.

Sending packs with precompiled structs (pymavlink's message objects only for the
low-rate rest); receiving parses frames with struct and decodes the message types we
handle at rate (`FAST_IDS`) straight into pymavlink's message classes, falling back to
pymavlink's own decoder for every other type.  Accept/reject decisions and the count of
bad fragments equal pymavlink's parser (robust mode) datagram by datagram
(tests/unit/test_mavlink_fastparse.py pins both).  No mavutil: it keeps process-wide state.
A UDP datagram carries whole packets, so each is parsed on its own; bytes a datagram
leaves unparsed can never corrupt the next one.
"""

from __future__ import annotations

import re
import struct
import time
from collections import Counter
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink2
from pymavlink.dialects.v20.common import MAVError, mcrf4xx
from pymavlink.dialects.v20.common import MAVLink_message as MAVLinkMessage

from agents.mavlink.signing import SignatureVerifier, signature, signing_timestamp

STX_V2, STX_V1 = 0xFD, 0xFE
_MARKER = re.compile(b"[\xfd\xfe]")
_HEADER_V2 = struct.Struct("<BBBBBBBHB")
_HEADER_V1 = struct.Struct("<BBBBBB")
_STAMP = struct.Struct("<BQ")
# Types decoded without pymavlink's parser: what flows at the control rate, and the
# status and command traffic around it.  Each has scalar fields only (no arrays, no text).
FAST_IDS = (0, 1, 2, 24, 30, 32, 33, 74, 75, 76, 77, 84, 111, 245)


def new_codec(sysid: int, compid: int) -> mavlink2.MAVLink:
    """An encoder/decoder that sends MAVLink 2 as (sysid, compid) and never raises on input."""
    mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.robust_parsing = True
    return mav


def sign_outgoing(mav: mavlink2.MAVLink, key: bytes, link_id: int, timestamp: int) -> None:
    """Sign every packet `mav` packs from now on (MAVLink 2 signing, agents.mavlink.signing).

    Only for a codec that sends: pymavlink's receive-side check is not trusted (it moves a
    stream's timestamp before it verifies), so received frames go to a SignatureVerifier.
    """
    mav.signing.secret_key = key
    mav.signing.link_id = link_id & 0xFF
    mav.signing.timestamp = timestamp
    mav.signing.sign_outgoing = True


def signature_ok(verifier: SignatureVerifier | None, msg: MAVLinkMessage,
                 counters: Counter[str]) -> bool:
    """Whether a received message passes `verifier` (always, when there is none); a
    rejection is counted as signing_rejected_<reason>.  Never raises: a frame must not
    stop the receiver."""
    if verifier is None:
        return True
    try:
        header = msg._header
        reason = verifier.check(frame_bytes(msg), header.msgId, header.srcSystem,
                                header.srcComponent)
    except Exception:  # hostile bytes: counted below
        reason = "error"
    if reason is not None:
        counters[f"signing_rejected_{reason}"] += 1
    return reason is None


def frame_bytes(msg: MAVLinkMessage) -> bytes:
    """The received frame of `msg` as it came off the wire, signature block included."""
    return bytes(msg.get_msgbuf())


# ---- receive ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Decoded:
    """Good messages of one datagram and how many bad fragments it held."""

    messages: tuple[MAVLinkMessage, ...]
    bad: int


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
_FAST = {i: _FastType(mavlink2.mavlink_map[i]) for i in FAST_IDS}
_KNOWN = frozenset(mavlink2.mavlink_map)
_Header = mavlink2.MAVLink_header


def decode_datagram(mav: mavlink2.MAVLink, data: bytes) -> Decoded:
    """Parse one datagram; garbage, CRC errors and truncation become a `bad` count.

    Framing follows pymavlink's robust parser: a run of bytes that starts no frame is one
    bad fragment, and so is an incomplete frame at the end.  `mav` decodes the types not
    in FAST_IDS (all of them, if it checks signatures itself)."""
    if type(data) is not bytes:  # a bytearray or memoryview: frames are sliced as bytes
        data = bytes(data)
    keyed = mav.signing.secret_key is not None
    good: list[MAVLinkMessage] = []
    bad, i, n = 0, 0, len(data)
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
            msg = None if flags & 0xFE else _decode_frame(mav, frame, keyed)
        except MAVError:
            msg = None
        except Exception:  # pymavlink raises assorted errors on hostile input; drop it all
            return Decoded((), 1)
        if msg is None:
            bad += 1
        else:
            good.append(msg)
    return Decoded(tuple(good), bad)


def _decode_frame(mav: mavlink2.MAVLink, frame: bytes, keyed: bool) -> MAVLinkMessage | None:
    """One whole frame as a message, or None when it is bad (CRC, unknown type)."""
    if frame[0] == STX_V2:
        _, mlen, flags, compat, seq, sysid, compid, low, high = _HEADER_V2.unpack_from(frame)
        msg_id, start = low | high << 16, 10
    else:
        _, mlen, seq, sysid, compid, msg_id = _HEADER_V1.unpack_from(frame)
        flags = compat = 0
        start = 6
    fast = _FAST.get(msg_id)
    if fast is None or keyed:
        if msg_id not in _KNOWN:
            return None
        return mav.decode(bytearray(frame))
    crc_at = start + mlen
    crc = frame[crc_at] | frame[crc_at + 1] << 8
    if mcrf4xx(frame[1:crc_at] + fast.extra, 0xFFFF) != crc:
        return None
    payload = frame[start:crc_at]
    if mlen != fast.size:  # MAVLink 2 drops trailing zeros; longer payloads are cut
        payload = payload[:fast.size].ljust(fast.size, b"\0")
    msg: MAVLinkMessage = object.__new__(fast.cls)
    fields = dict(fast.fixed)
    fields.update(zip(fast.names, fast.unpack(payload), strict=True))
    fields["_header"] = _Header(msg_id, flags, compat, mlen, seq, sysid, compid)
    fields["_msgbuf"], fields["_payload"], fields["_crc"] = frame, frame[6:crc_at], crc
    fields["_signed"], fields["_link_id"] = False, None
    msg.__dict__ = fields
    return msg


# ---- send -------------------------------------------------------------------------------
def encode(mav: mavlink2.MAVLink, msg: MAVLinkMessage) -> bytes:
    """Pack as the next packet of `mav`'s stream (pymavlink's pack() leaves seq alone)."""
    _advance_signing_clock(mav)
    data: bytes = msg.pack(mav)
    mav.seq = (mav.seq + 1) & 0xFF
    return data


def encode_fields(mav: mavlink2.MAVLink, msg_cls: type[MAVLinkMessage], *fields: float) -> bytes:
    """Pack a message straight from its fields in wire order (`ordered_fieldnames`),
    skipping the message object: the same bytes as `encode(mav, msg_cls(...))`, several
    times faster.  For the messages sent at the control rate."""
    return encode_payload(mav, msg_cls.id, msg_cls.crc_extra, msg_cls.unpacker.pack(*fields))


def encode_payload(mav: mavlink2.MAVLink, msg_id: int, crc_extra: int, payload: bytes) -> bytes:
    """Frame a packed payload as the next MAVLink 2 packet of `mav`'s stream.

    Also for messages this pymavlink's dialect lacks (PROTOCOL_VERSION, id 300).
    """
    payload = payload.rstrip(b"\x00") or payload[:1]
    signing = mav.signing
    signed = signing.sign_outgoing
    body = _HEADER_V2.pack(STX_V2, len(payload), 1 if signed else 0, 0, mav.seq, mav.srcSystem,
                           mav.srcComponent, msg_id & 0xFFFF, msg_id >> 16) + payload
    mav.seq = (mav.seq + 1) & 0xFF
    frame = body + mcrf4xx(body[1:] + bytes((crc_extra,)), 0xFFFF).to_bytes(2, "little")
    if not signed:
        return frame
    _advance_signing_clock(mav)
    stamped = frame + _STAMP.pack(signing.link_id, signing.timestamp)[:7]
    signing.timestamp += 1
    return stamped + signature(signing.secret_key, stamped)


def _advance_signing_clock(mav: mavlink2.MAVLink) -> None:
    """Keep a signing stream's timestamp on the wall clock, as the spec asks of a system
    that has one.  pymavlink only adds 1 per packet, so a long-lived stream falls minutes
    behind real time and a receiver that restarts rejects it as a stale new stream."""
    if mav.signing.sign_outgoing:
        mav.signing.timestamp = max(mav.signing.timestamp, signing_timestamp(time.time()))
