"""The struct receive path (agents.mavlink.wire.decode_datagram) pinned to pymavlink's parser.

Random valid frames of every fast type give the same message objects (fields, header,
raw bytes); random garbage, truncated, mutated and spliced datagrams give the same good
messages, the same bad-fragment count, and the same signing verdicts.
"""

from __future__ import annotations

import math
import struct
from collections import Counter
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2
from pymavlink.dialects.v20.common import mcrf4xx

from agents.mavlink.signing import SignatureVerifier, signing_timestamp
from agents.mavlink.wire import encode, new_codec, sign_outgoing, signature_ok
from agents.mavlink.wire_decode import FAST_IDS, MAVLinkMessage, decode_datagram

pytestmark = pytest.mark.timeout(120)
KEY = bytes(range(1, 33))
HEADER_V2 = struct.Struct("<BBBBBBBHB")
HEADER_V1 = struct.Struct("<BBBBBB")
FAST_CLASSES = tuple(mavlink2.mavlink_map[i] for i in FAST_IDS)
# Slow-path types seen on our links: parameters, text, arrays.
OTHER_CLASSES = tuple(mavlink2.mavlink_map[i] for i in (20, 23, 242, 253, 147, 39))
SETTINGS = settings(max_examples=300, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


def reference(data: bytes) -> tuple[list[MAVLinkMessage], int, int]:
    """The receive path before the struct parser: pymavlink's robust parse_buffer.  Its
    good messages, bad fragments, and frames of types it does not know (UNKNOWN_<id>)."""
    mav = new_codec(250, 0)
    try:
        parsed = mav.parse_buffer(data) or []
    except Exception:
        return [], 1, 0
    unknown = sum(m.get_type().startswith("UNKNOWN") for m in parsed)
    good = [m for m in parsed if m.get_type() != "BAD_DATA"
            and not m.get_type().startswith("UNKNOWN")]
    return good, len(parsed) - len(good) - unknown + (1 if mav.buf_len() > 0 else 0), unknown


def norm(value: Any) -> Any:
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    if isinstance(value, float):
        return repr(value) if math.isnan(value) else value
    if isinstance(value, list):
        return [norm(v) for v in value]
    return value


def summary(msg: MAVLinkMessage) -> tuple[type, dict[str, Any], dict[str, Any]]:
    fields = {k: norm(v) for k, v in vars(msg).items() if k != "_header"}
    return type(msg), fields, vars(msg.get_header())


def frame(cls: type[MAVLinkMessage], payload: bytes, seq: int, sysid: int, compid: int,
          v1: bool = False, signature: bytes | None = None, compat: int = 0,
          incompat: int = 0) -> bytes:
    """One frame of `cls` around any payload bytes, with a correct CRC."""
    if v1:
        body = HEADER_V1.pack(0xFE, len(payload), seq, sysid, compid, cls.id) + payload
    else:
        flags = incompat | (0 if signature is None else 1)
        body = HEADER_V2.pack(0xFD, len(payload), flags, compat, seq, sysid, compid,
                              cls.id & 0xFFFF, cls.id >> 16) + payload
    crc = mcrf4xx(body[1:] + bytes((cls.crc_extra,)), 0xFFFF).to_bytes(2, "little")
    return body + crc + (signature or b"")


@st.composite
def frames(draw: st.DrawFn, classes: tuple[type[MAVLinkMessage], ...] = FAST_CLASSES) -> bytes:
    cls = draw(st.sampled_from(classes))
    size = cls.unpacker.size
    v1 = cls.id < 256 and size < 256 and draw(st.booleans())
    # Shorter (MAVLink 2 truncation), exact, or longer (a newer dialect's extensions).
    length = draw(st.integers(0 if not v1 else size, min(255, size + 8)))
    payload = draw(st.binary(min_size=length, max_size=length))
    signature = None if v1 or draw(st.booleans()) else draw(st.binary(min_size=13, max_size=13))
    return frame(cls, payload, draw(st.integers(0, 255)), draw(st.integers(0, 255)),
                 draw(st.integers(0, 255)), v1, signature, draw(st.sampled_from((0, 0, 1, 255))),
                 draw(st.sampled_from((0, 0, 0, 2, 0x80))))


def assert_same(data: bytes) -> None:
    ours = decode_datagram(new_codec(250, 0), data)
    good, bad, unknown = reference(data)
    assert (ours.bad, ours.unknown) == (bad, unknown)
    assert [summary(m) for m in ours.messages] == [summary(m) for m in good]


@SETTINGS
@given(frames())
def test_valid_frames_of_fast_types_decode_as_pymavlink_does(data: bytes) -> None:
    decoded = decode_datagram(new_codec(250, 0), data)
    assert len(decoded.messages) + decoded.bad == 1  # bad: an incompat flag we do not know
    assert_same(data)


@SETTINGS
@given(st.lists(frames(FAST_CLASSES + OTHER_CLASSES), min_size=1, max_size=4), st.data())
def test_mutated_datagrams_get_the_same_verdicts(parts: list[bytes], data: st.DataObject) -> None:
    blob = bytearray(b"".join(parts))
    for _ in range(data.draw(st.integers(0, 3))):
        at = data.draw(st.integers(0, len(blob)))
        action = data.draw(st.sampled_from(("flip", "cut", "insert", "delete")))
        if action == "flip" and at < len(blob):
            blob[at] ^= data.draw(st.integers(1, 255))
        elif action == "cut":
            del blob[at:]
        elif action == "insert":
            blob[at:at] = data.draw(st.binary(min_size=1, max_size=6))
        elif action == "delete":
            del blob[at:at + data.draw(st.integers(1, 4))]
    assert_same(bytes(blob))


@SETTINGS
@given(st.binary(max_size=300))
def test_garbage_gets_the_same_verdicts(data: bytes) -> None:
    assert_same(data)
    assert_same(b"\xfd" + data)
    assert_same(b"\xfe" + data)


def signed_stream(count: int) -> list[bytes]:
    tx = new_codec(1, 1)
    sign_outgoing(tx, KEY, 0, signing_timestamp(1.8e9))
    return [encode(tx, tx.local_position_ned_encode(k, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0))
            for k in range(count)]


@SETTINGS
@given(st.lists(st.tuples(st.integers(0, 5), st.integers(-1, 40), st.integers(0, 255)),
                max_size=8))
def test_signing_verdicts_equal_on_forged_replayed_and_unsigned(
        edits: list[tuple[int, int, int]]) -> None:
    """Each datagram of a signed stream, replayed, reordered or with a byte changed (-1:
    sent unsigned), is judged the same whichever parser read it."""
    stream = signed_stream(6)
    datagrams = []
    for index, at, value in edits:
        data = bytearray(stream[index])
        if at < 0:
            data = bytearray(new_codec(1, 1).local_position_ned_encode(1, 0, 0, 0, 0, 0, 0)
                             .pack(new_codec(1, 1)))
        elif at < len(data):
            data[at] = value
        datagrams.append(bytes(data))
    ours, theirs = SignatureVerifier(KEY, clock=lambda: 1.8e9), SignatureVerifier(
        KEY, clock=lambda: 1.8e9)
    ours_counts: Counter[str] = Counter()
    their_counts: Counter[str] = Counter()
    for datagram in datagrams:
        a = [signature_ok(ours, m, ours_counts)
             for m in decode_datagram(new_codec(2, 1), datagram).messages]
        b = [signature_ok(theirs, m, their_counts) for m in reference(datagram)[0]]
        assert a == b
    assert ours_counts == their_counts and ours.counters == theirs.counters


def test_keyed_codec_decodes_through_pymavlink() -> None:
    """A codec that checks signatures itself keeps doing so (everything goes to pymavlink)."""
    rx = new_codec(2, 1)
    sign_outgoing(rx, KEY, 0, 0)
    good = signed_stream(2)
    forged = bytearray(good[1])
    forged[-1] ^= 1
    assert len(decode_datagram(rx, good[0]).messages) == 1
    assert decode_datagram(rx, bytes(forged)).bad == 1


def test_any_bytes_like_datagram_is_read() -> None:
    frame = signed_stream(1)[0]
    for data in (frame, bytearray(frame), memoryview(frame)):
        decoded = decode_datagram(new_codec(2, 1), data)  # type: ignore[arg-type]
        assert len(decoded.messages) == 1 and decoded.bad == 0
