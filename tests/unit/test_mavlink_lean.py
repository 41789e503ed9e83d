"""The agents' lean MAVLink dialect (agents/mavlink/lean_common.py) pinned to the full
common dialect and to its generator: same messages on the wire, both ways, signed or not;
hostile bytes never raise; types it lacks are counted apart from bad bytes."""

from __future__ import annotations

import math
import struct
from importlib.metadata import version
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2

from agents.mavlink import lean_common, lean_gen
from agents.mavlink.signing import signing_timestamp
from agents.mavlink.wire import encode, encode_fields, new_codec, sign_outgoing
from agents.mavlink.wire_decode import FAST_IDS, MAVLinkMessage, decode_datagram

pytestmark = pytest.mark.timeout(120)
KEY = bytes(range(32))
HEADER_V2 = struct.Struct("<BBBBBBBHB")
LEAN_CLASSES = tuple(lean_common.mavlink_map[i] for i in sorted(lean_common.mavlink_map))
SETTINGS = settings(max_examples=200, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])
# What must stay equal between a lean class and its full-dialect twin: all of the wire
# (id, CRC extra, struct, field order and types) and what readers use (names, enums, units).
PINNED = ("id", "msgname", "crc_extra", "ordered_fieldnames", "fieldnames", "fieldtypes",
          "array_lengths", "orders", "lengths", "fielddisplays_by_name", "fieldenums_by_name",
          "fieldunits_by_name", "instance_field", "instance_offset")


def test_the_lean_messages_are_the_full_dialects_and_cover_what_the_agents_use() -> None:
    assert set(lean_common.mavlink_map) == set(lean_gen.LEAN_MESSAGES)
    # The fast decoder's types, and every type the adapter and its start-up handle or send.
    used = {0, 32, 33, 76, 77, 84, 111, 242, 253}
    assert set(FAST_IDS) | used <= set(lean_common.mavlink_map)
    assert len(lean_common.enums) == 0  # the tables are what the lean dialect leaves out
    for cls in LEAN_CLASSES:
        full = mavlink2.mavlink_map[cls.id]
        assert lean_gen.LEAN_MESSAGES[cls.id] == cls.msgname
        for name in PINNED:
            assert getattr(cls, name) == getattr(full, name), (cls.msgname, name)
        assert cls.unpacker.format == full.unpacker.format, cls.msgname
    # An extension field is what moves a class's CRC extra if it is wrongly made a base one.
    assert lean_common.mavlink_map[253].fieldnames[-2:] == ["id", "chunk_seq"]


@pytest.mark.timeout(60)
def test_regenerating_gives_the_committed_module() -> None:
    committed = lean_gen.OUTPUT.read_text(encoding="utf-8")
    if not committed.startswith(lean_gen.header().split("\n", 1)[0]):
        # Another pymavlink than the one it was made with (pyproject asks >= 2.4.40): its
        # generator may write other text for the same messages.  The test above still pins
        # every message to this pymavlink's full dialect.
        pytest.skip(f"lean_common.py was generated with another pymavlink than "
                    f"{version('pymavlink')}: python -m agents.mavlink.lean_gen")
    assert lean_gen.generate() == committed, (
        "agents/mavlink/lean_common.py is stale: python -m agents.mavlink.lean_gen")


def crc_frame(cls: type[MAVLinkMessage], payload: bytes, seq: int, sysid: int,
              signature: bytes | None) -> bytes:
    """A MAVLink 2 frame of `cls` (of either dialect) around any payload bytes, with a
    correct CRC."""
    flags = 0 if signature is None else 1
    body = HEADER_V2.pack(0xFD, len(payload), flags, 0, seq, sysid, 1, cls.id & 0xFFFF,
                          cls.id >> 16) + payload
    crc = lean_common.mcrf4xx(body[1:] + bytes((cls.crc_extra,)), 0xFFFF)
    return body + crc.to_bytes(2, "little") + (signature or b"")


# Full-dialect types a real autopilot or ground station sends that the lean one lacks.
OTHER_CLASSES = tuple(mavlink2.mavlink_map[i] for i in (22, 31, 36, 65, 141, 147, 230, 241))


@st.composite
def lean_frames(draw: st.DrawFn, classes: tuple[type, ...] = LEAN_CLASSES) -> bytes:
    cls = draw(st.sampled_from(classes))
    size = cls.unpacker.size
    length = draw(st.integers(0, min(255, size + 8)))  # truncated, exact or longer
    signature = draw(st.none() | st.binary(min_size=13, max_size=13))
    return crc_frame(cls, draw(st.binary(min_size=length, max_size=length)),
                     draw(st.integers(0, 255)), draw(st.integers(1, 255)), signature)


def norm(value: Any) -> Any:
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    if isinstance(value, list):
        return [norm(v) for v in value]
    return bytes(value) if isinstance(value, bytearray) else value


def summary(msg: MAVLinkMessage) -> tuple[str, dict[str, Any], dict[str, Any]]:
    """A message as its dialect-free content: type name, every attribute, header."""
    fields = {k: norm(v) for k, v in vars(msg).items() if k != "_header"}
    return msg.get_type(), fields, vars(msg.get_header())


def decoded_by_pymavlink(dialect: Any, data: bytes) -> list[tuple[str, dict, dict]]:
    mav = new_codec(9, 0, dialect)
    return [summary(m) for m in mav.parse_buffer(data) or []]


@SETTINGS
@given(lean_frames())
def test_any_frame_of_a_lean_type_decodes_alike_in_both_dialects(data: bytes) -> None:
    lean = decode_datagram(new_codec(9, 0, lean_common), data)
    full = decode_datagram(new_codec(9, 0, mavlink2), data)
    assert len(lean.messages) == 1 and (lean.bad, lean.unknown) == (0, 0)
    assert [summary(m) for m in lean.messages] == [summary(m) for m in full.messages]
    assert decoded_by_pymavlink(lean_common, data) == decoded_by_pymavlink(mavlink2, data)


def fields_of(msg: MAVLinkMessage) -> list[Any]:
    """Constructor arguments that rebuild `msg` (text fields as their raw bytes)."""
    return [getattr(msg, f"_{name}_raw", getattr(msg, name)) for name in msg.fieldnames]


def codecs(signed: bool) -> tuple[Any, Any]:
    lean, full = new_codec(3, 1, lean_common), new_codec(3, 1, mavlink2)
    if signed:  # a stamp ahead of the wall clock, which both then keep (not time.time())
        for mav in (lean, full):
            sign_outgoing(mav, KEY, 7, signing_timestamp(2.5e9))
    return lean, full


@SETTINGS
@given(lean_frames(), st.booleans())
def test_the_lean_codec_sends_the_bytes_common_sends_and_each_reads_the_other(
        data: bytes, signed: bool) -> None:
    msg = decode_datagram(new_codec(9, 0, lean_common), data).messages[0]
    values = fields_of(msg)
    lean, full = codecs(signed)
    ours = encode(lean, type(msg)(*values))
    theirs = encode(full, mavlink2.mavlink_map[type(msg).id](*values))
    assert ours == theirs and len(ours) > 12
    if type(msg).id in FAST_IDS:  # struct packing, as the setpoint stream sends
        packed = [getattr(msg, f"_{n}_raw", getattr(msg, n)) for n in msg.ordered_fieldnames]
        assert encode_fields(lean, type(msg), *packed) == encode(full, type(msg)(*values))
    read_by_full = decode_datagram(new_codec(9, 0, mavlink2), ours)
    read_by_lean = decode_datagram(new_codec(9, 0, lean_common), theirs)
    assert [summary(m) for m in read_by_full.messages] == [
        summary(m) for m in read_by_lean.messages] and len(read_by_lean.messages) == 1


@SETTINGS
@given(st.lists(st.one_of(lean_frames(), lean_frames(OTHER_CLASSES), st.binary(max_size=80),
                          st.builds(lambda b: b"\xfd" + b, st.binary(max_size=60))),
                max_size=5), st.data())
def test_hostile_datagrams_never_raise_and_every_fragment_is_counted_once(
        parts: list[bytes], data: st.DataObject) -> None:
    blob = bytearray(b"".join(parts))
    for _ in range(data.draw(st.integers(0, 4))):  # flips, cuts: any bytes at all
        at = data.draw(st.integers(0, max(0, len(blob) - 1)))
        if blob and data.draw(st.booleans()):
            blob[at] ^= data.draw(st.integers(1, 255))
        else:
            del blob[at:at + data.draw(st.integers(1, 8))]
    for dialect in (lean_common, mavlink2):
        got = decode_datagram(new_codec(9, 0, dialect), bytes(blob))
        assert (len(got.messages), got.unknown, got.bad) == sorted_by_pymavlink(dialect, blob)


def sorted_by_pymavlink(dialect: Any, data: bytes | bytearray) -> tuple[int, int, int]:
    """How pymavlink's robust parser sorts the fragments of `data`: good, unknown, bad."""
    rx = new_codec(9, 0, dialect)
    try:
        kinds = [m.get_type() for m in rx.parse_buffer(bytes(data)) or []]
    except Exception:  # as decode_datagram: the whole datagram is one bad fragment
        return 0, 0, 1
    unknown = sum(k.startswith("UNKNOWN") for k in kinds)
    bad = kinds.count("BAD_DATA")
    return len(kinds) - unknown - bad, unknown, bad + (1 if rx.buf_len() > 0 else 0)


def test_a_full_dialect_type_is_unknown_to_the_lean_codec_not_bad() -> None:
    gcs = new_codec(1, 1, mavlink2)
    battery = encode(gcs, gcs.battery_status_encode(0, 0, 0, 2500, [3700] * 10, -1, -1, -1, 80))
    assert 147 not in lean_common.mavlink_map
    position = encode(gcs, gcs.local_position_ned_encode(1, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0))
    lean = decode_datagram(new_codec(9, 0, lean_common), battery + position + b"\x00junk")
    assert (lean.unknown, lean.bad) == (1, 1)
    assert [m.get_type() for m in lean.messages] == ["LOCAL_POSITION_NED"]
    full = decode_datagram(new_codec(9, 0, mavlink2), battery + position)
    assert (full.unknown, full.bad, len(full.messages)) == (0, 0, 2)
    # An id no dialect here defines is unknown to the full one too, signed or not.
    odd = crc_frame(lean_common.MAVLink_heartbeat_message, b"\x01", 0, 1, bytes(13))
    odd = odd[:7] + (60001).to_bytes(3, "little") + odd[10:]
    assert 60001 not in mavlink2.mavlink_map
    keyed = new_codec(9, 0, mavlink2)
    keyed.signing.secret_key = KEY
    for rx in (new_codec(9, 0, mavlink2), keyed, new_codec(9, 0, lean_common)):
        assert decode_datagram(rx, odd).unknown == 1
