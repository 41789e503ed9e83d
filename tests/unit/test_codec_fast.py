"""The codec's fast twins (transport.codec_fast) pinned to the reference schema walk.

For valid messages and for hostile ones (random msgpack, mutated wire arrays at any depth,
wrong types, bools for ints, NaN/inf, wrong lengths, older versions), `encode` / `decode`
give exactly what `encode_reference` / `decode_reference` give: the same bytes, an equal
message with the same Python types, or a CodecError with the same reason and text.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from errors import CodecError
from transport import codec, codec_fast
from transport.codec import decode, decode_reference, encode, encode_reference
from transport.messages import (
    PROCESS_STATES,
    ClockProbe,
    FollowerState,
    Header,
    Message,
    ProcessStatus,
    RunControl,
    TargetObservation,
    TruthSnapshot,
)

pytestmark = pytest.mark.timeout(120)

# Valid values: every finite float (huge ones overflow the twins' sums: reference path).
fl = st.floats(allow_nan=False, allow_infinity=False) | st.sampled_from([0.0, -0.0, 1e308])
nat = st.integers(0, 2**64 - 1)
name = st.text(max_size=12) | st.just("x" * 256)
v2 = st.tuples(fl, fl)
v3 = st.tuples(fl, fl, fl)
header = st.builds(Header, name, nat, fl)
link = st.tuples(nat, fl, fl)
# A law's fields (transport.law_fields): a float, a plane vector, or per-neighbour vectors.
law = st.dictionaries(st.text(min_size=1, max_size=8) | st.just("x" * 64),
                      fl | v2 | st.lists(link, max_size=4).map(tuple), max_size=5)

MESSAGES = st.one_of(
    st.builds(FollowerState, header, nat, v2, v2, v2, v2, v2, fl, law),
    st.builds(TargetObservation, header, nat, nat, v2, fl, st.none() | fl),
    st.builds(TruthSnapshot, header, fl, st.lists(v3, max_size=5).map(tuple),
              st.lists(v3, max_size=5).map(tuple), st.lists(v2, max_size=3).map(tuple),
              st.lists(v2, max_size=3).map(tuple)),
    st.builds(ProcessStatus, header, name, nat, st.sampled_from(PROCESS_STATES),
              st.dictionaries(name, st.integers(-2**63, 2**64 - 1), max_size=4), name),
    st.builds(RunControl, header, st.sampled_from(["start", "stop"]), fl, fl),
    st.builds(ClockProbe, header, fl, st.lists(st.tuples(name, fl, fl), max_size=4).map(tuple)),
)

# What hostile input puts anywhere: every msgpack type, the edge values of each rule.
JUNK = st.one_of(
    st.sampled_from([True, False, None, 0, -1, 1, 2**64 - 1, -2**63, 1.5, -0.0, math.nan,
                     math.inf, -math.inf, 1e308, "", "x" * 257, "start", "running", b"ab",
                     [], [1.0], [1.0, 2.0], [1, 2], [1.0, 2.0, 3.0], [True, 1.0],
                     [math.nan, 1.0], {"a": 1}, {"a": True}, {"a": 1.0},
                     [[1.0, 2.0]], [[0, 1.0, 2.0, 3.0, 4.0]], [["p", 1.0, 2.0]],
                     msgpack.ExtType(1, b"ab")]),
    st.recursive(st.none() | st.booleans() | st.integers(-2**63, 2**64 - 1)
                 | st.floats() | st.text(max_size=4) | st.binary(max_size=4),
                 lambda inner: st.lists(inner, max_size=6), max_leaves=12),
)


H = Header("follower-1", 3, 1.5)
SAMPLES: list[Message] = [
    FollowerState(H, 1, (1.0, 2.0), (0.0, 0.5), (1.0, 1.0), (0.0, 0.0), (0.0, -0.5), 1.0,
                  {"phi_m": (0.25, 0.0), "sums": ((0, 1.0, 2.0), (2, -1.0, 0.0)),
                   "gain": 0.5, "none": ()}),
    TargetObservation(H, 1, 0, (1.0, 2.0), 1.0, 0.1),
    TargetObservation(H, 1, 0, (1.0, 2.0), 1.0, None),
    TruthSnapshot(H, 1.0, ((1.0, 2.0, 3.0), (0.0, 0.5, 1.0)), ((0.0, 0.0, 0.0),) * 2,
                  ((1.0, 1.0),), ((0.0, 0.0),)),
    ProcessStatus(H, "sim", 0, "running", {"a": 1, "b": -2}, "ok"),
    RunControl(H, "start", 1.0, 10.0),
    ClockProbe(H, 1.0, (("sim-0", 1.0, 2.0), ("launcher-0", 0.5, 0.25))),
]
EDGES: list[Any] = [True, False, None, 0, -1, 1, 2**64 - 1, 1.5, -0.0, math.nan, math.inf,
                    -math.inf, 1e308, "", "x" * 257, "stop", b"ab", [], [1.0], [1.0, 2.0],
                    [1, 2], [1.0, 2.0, 3.0], [True, 1.0], [math.nan, 1.0], {"a": 1},
                    {"a": True}, [[1.0, 2.0]], [[0, 1.0, 2.0, 3.0, 4.0]], [["p", 1.0, 2.0]],
                    msgpack.ExtType(1, b"ab"),
                    *(item * n for n in (256, 257) for item in (
                        [[1.0, 2.0]], [[1.0, 2.0, 3.0]], [[0, 1.0, 2.0, 3.0, 4.0]],
                        [["p", 1.0, 2.0]])),
                    {str(k): 0 for k in range(256)}, {str(k): 0 for k in range(257)},
                    # law fields (transport.law_fields): each kind, and each limit
                    {"a": [1.0, 2.0]}, {"a": [[0, 1.0, 2.0]]}, {"a": [[0, 1.0, 2.0]] * 257},
                    {"a": [1, 2.0]}, {"a": [[1.0, 2.0]]}, {"a": [[-1, 1.0, 2.0]]}, {"": 1.0},
                    {"a" * 65: 1.0}, {str(k): 1.0 for k in range(16)},
                    {str(k): 1.0 for k in range(17)}, {"a": [math.nan, 1.0]}, {"a": []}]


def typed(x: Any) -> Any:
    """`x` with the type of every value in it: equal messages with an int where the
    other has a float, or a list where it has a tuple, must not compare equal here."""
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return (type(x).__name__, tuple(typed(getattr(x, f.name)) for f in dataclasses.fields(x)))
    if isinstance(x, tuple | list):
        return (type(x).__name__, tuple(typed(v) for v in x))
    if isinstance(x, dict):
        return ("dict", tuple((typed(k), typed(v)) for k, v in x.items()))
    return (type(x).__name__, repr(x))


def outcome(fn: Any, arg: Any) -> Any:
    try:
        out = fn(arg)
    except CodecError as exc:
        return ("error", exc.reason, str(exc))
    return ("ok", out if isinstance(out, bytes) else typed(out))


def same_decode(payload: bytes) -> Any:
    fast = outcome(decode, payload)
    assert fast == outcome(decode_reference, payload)
    return fast


def test_every_control_rate_message_has_a_live_twin() -> None:
    """A schema change without a new twin would silently fall back to the slow path.  The
    low-rate messages have none: the schema walk is cheap enough at their rate."""
    fast = {FollowerState, TargetObservation, TruthSnapshot}
    assert set(codec.FAST_ENCODERS) == fast
    assert {codec.SCHEMAS[cls][0] for cls in fast} == set(codec.FAST_DECODERS)
    for msg in (m for m in SAMPLES if type(m) in fast):
        wire = codec.FAST_ENCODERS[type(msg)](msg)
        assert wire is not None, type(msg).__name__
        obj = msgpack.unpackb(encode(msg))
        assert codec.FAST_DECODERS[obj[1]][1](obj) == msg


@settings(max_examples=200, deadline=None)
@given(MESSAGES)
def test_valid_messages_same_bytes_and_same_message(msg: Message) -> None:
    payload = encode(msg)
    assert payload == encode_reference(msg)
    assert same_decode(payload) == ("ok", typed(msg))


def mutate(data: st.DataObject, node: Any) -> Any:
    """`node` with one change somewhere inside: replaced, dropped, or one item added."""
    if not isinstance(node, list) or not node or data.draw(st.integers(0, 4)) == 0:
        return data.draw(JUNK)
    k = data.draw(st.integers(0, len(node) - 1))
    op = data.draw(st.sampled_from(["deeper", "deeper", "drop", "add"]))
    if op == "drop":
        return node[:k] + node[k + 1:]
    if op == "add":
        return [*node[:k], data.draw(JUNK), *node[k:]]
    return [*node[:k], mutate(data, node[k]), *node[k + 1:]]


@settings(max_examples=400, deadline=None)
@given(MESSAGES, st.data())
def test_mutated_wire_arrays_same_outcome(msg: Message, data: st.DataObject) -> None:
    wire = msgpack.unpackb(encode_reference(msg))
    for _ in range(data.draw(st.integers(1, 3))):
        wire = mutate(data, wire)
    same_decode(bytes(msgpack.packb(wire)))


@settings(max_examples=150, deadline=None)
@given(MESSAGES)
def test_older_and_newer_versions_same_outcome(msg: Message) -> None:
    wire = msgpack.unpackb(encode_reference(msg))
    for version in (1, 2, 4, 3.0, True):
        same_decode(bytes(msgpack.packb([version, *wire[1:]])))
    if isinstance(msg, FollowerState):  # before v4 the paper's law had fixed fields
        for version in (1, 2, 3):
            assert same_decode(bytes(msgpack.packb([version, *wire[1:]])))[1] == "version"


@settings(max_examples=150, deadline=None)
@given(st.lists(JUNK, max_size=12) | JUNK | st.binary(max_size=64))
def test_random_payloads_same_outcome(junk: Any) -> None:
    same_decode(junk if isinstance(junk, bytes) else bytes(msgpack.packb(junk)))


def junk_field(data: st.DataObject, value: Any) -> Any:
    """`value` replaced by something of another type, or with one bad item inside."""
    extra = [np.float64(1.0), np.float32(1.0), np.int64(1), (1.0, 2.0), [1.0, 2.0],
             {1.0, 2.0}, {1.0: 0, 2.0: 0}, (1.0, 2.0, 3.0), ((1.0, 2.0),), ((0, 1.0, 2.0),)]
    if isinstance(value, tuple) and value and data.draw(st.booleans()):
        k = data.draw(st.integers(0, len(value) - 1))
        return (*value[:k], junk_field(data, value[k]), *value[k + 1:])
    return data.draw(JUNK | st.sampled_from(extra))


@settings(max_examples=300, deadline=None)
@given(MESSAGES, st.data())
def test_encoding_bad_fields_same_outcome(msg: Message, data: st.DataObject) -> None:
    names = ["header.sender_id", "header.seq", "header.stamp_s",
             *(f.name for f in dataclasses.fields(msg) if f.name != "header")]
    field = data.draw(st.sampled_from(names))
    if field.startswith("header."):
        sub = field.split(".")[1]
        bad_header = dataclasses.replace(
            msg.header, **{sub: junk_field(data, getattr(msg.header, sub))})
        bad = dataclasses.replace(msg, header=bad_header)
    else:
        bad = dataclasses.replace(
            msg, **{field: junk_field(data, getattr(msg, field))})
    fast, ref = outcome(encode, bad), outcome(encode_reference, bad)
    assert fast == ref


def paths(node: Any, at: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Where something can be put in a wire array or a message field: every item, deep."""
    inner: list[tuple[Any, ...]] = []
    if isinstance(node, list | tuple):
        for k, v in enumerate(node):
            inner += paths(v, (*at, k))
    elif isinstance(node, dict):
        for k, v in node.items():
            inner += paths(v, (*at, k))
    return [at, *inner] if at else inner


def put(node: Any, at: tuple[Any, ...], value: Any, drop: bool = False) -> Any:
    if not at:
        return value
    if isinstance(node, dict):
        out = dict(node)
        if drop and len(at) == 1:
            del out[at[0]]
        else:
            out[at[0]] = put(node[at[0]], at[1:], value, drop)
        return out
    k = at[0]
    if drop and len(at) == 1:
        return type(node)([*node[:k], *node[k + 1:]])
    return type(node)([*node[:k], put(node[k], at[1:], value, drop), *node[k + 1:]])


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: type(m).__name__)
def test_every_bad_value_anywhere_in_the_wire_same_outcome(msg: Message) -> None:
    """Exhaustive single faults: each edge value at each place, each item dropped, one
    added to each list, each version."""
    wire = msgpack.unpackb(encode(msg))
    for at in paths(wire):
        for value in EDGES:
            same_decode(bytes(msgpack.packb(put(wire, at, value))))
        same_decode(bytes(msgpack.packb(put(wire, at, None, drop=True))))
        target = _at(wire, at)
        if isinstance(target, list):
            same_decode(bytes(msgpack.packb(put(wire, at, [*target, 1.0]))))


def _at(node: Any, at: tuple[Any, ...]) -> Any:
    for k in at:
        node = node[k]
    return node


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: type(m).__name__)
def test_every_bad_value_in_every_field_same_encode(msg: Message) -> None:
    extra = [np.float64(1.0), np.float32(1.0), np.int64(1), (1.0, 2.0), {1.0, 2.0},
             {1.0: 0, 2.0: 0}, ((1.0, 2.0),), ((0, 1.0, 2.0, 3.0, 4.0),), [[1.0, 2.0]],
             {"a": (1.0, 2.0)}, {"a": ((0, 1.0, 2.0),)}, {"a": [1, 2.0]}, {"a": ()},
             {"": 1.0}, {"a" * 65: 1.0}, {str(k): 1.0 for k in range(17)}]
    fields = {"header": dataclasses.asdict(msg.header),
              **{f.name: getattr(msg, f.name) for f in dataclasses.fields(msg)[1:]}}
    for at in paths(fields):
        for value in [*EDGES, *extra]:
            bad = put(fields, at, value)
            try:
                built = type(msg)(**{**bad, "header": Header(**bad["header"])})
            except TypeError:  # the header itself replaced: not a message
                continue
            assert outcome(encode, built) == outcome(encode_reference, built), (at, value)


def test_nan_and_bools_fall_back_to_the_reference_reasons() -> None:
    """The twins give up and the reference names the reason (examples of the above)."""
    good = FollowerState(Header("follower-1", 0, 1.0), 1, (1.0, 2.0), (0.0, 0.0),
                         (1.0, 1.0), (0.0, 0.0), (0.0, 0.0), 1.0)
    assert codec_fast.enc_follower_state(dataclasses.replace(good, r_m=(math.nan, 0.0))) is None
    with pytest.raises(CodecError) as err:
        encode(dataclasses.replace(good, r_m=(math.nan, 0.0)))
    assert err.value.reason == "non_finite"
    wire = msgpack.unpackb(encode(good))
    wire[5] = True  # a bool index
    assert codec_fast.dec_follower_state(wire) is None
    assert same_decode(bytes(msgpack.packb(wire)))[1] == "type"
