"""Codec: round trips, versions, malformed input, non-finite numbers, decoder counters."""

from __future__ import annotations

import dataclasses
import math

import msgpack
import numpy as np
import pytest

from errors import CodecError
from transport import codec
from transport.bus import Received
from transport.codec import CODEC_VERSION, decode, encode
from transport.decoder import Decoder
from transport.messages import (
    FollowerState,
    Header,
    Message,
    ProcessStatus,
    RunControl,
    Stamper,
    TargetObservation,
    TruthSnapshot,
    vec2,
)

H = Header("follower-1", 7, 1700000000.123456)


def follower_state(**over: object) -> FollowerState:
    base = FollowerState(
        header=H,
        index=1,
        r_m=(1.0, 2.0),
        dr_m_s=(0.1, -0.2),
        pos_m=(10.0, -20.0),
        vel_m_s=(0.3, 0.4),
        u_m_s=(0.5, 0.6),
        vehicle_stamp_s=1699999999.9,
        law={"phi_m": (0.0, 0.5)},
    )
    return dataclasses.replace(base, **over)  # type: ignore[arg-type]


ALL_MESSAGES: list[Message] = [
    follower_state(),
    follower_state(law={}),
    follower_state(law={"phi_m": (0.0, 0.5), "link_sums_m": ((0, 0.5, -0.25), (2, -1.0, 2.0)),
                        "link_rates_m_s": ((0, 0.01, 0.0), (2, 0.0, -0.02)), "gain": 2.5,
                        "none_yet": ()}),
    TargetObservation(H, 1, 0, (3.0, 4.0), 1700000000.1, 0.05),
    TargetObservation(H, 2, 1, (3.0, 4.0), 1700000000.1),
    TruthSnapshot(
        H,
        12.5,
        ((0.0, 1.0, 10.0), (2.0, 3.0, 10.0)),
        ((0.1, 0.0, 0.0),) * 2,
        ((1.0, 1.0),),
        ((1.0, 0.5),),
    ),
    ProcessStatus(H, "follower", 1, "linked", {"drop_msgpack": 3, "overruns": 0}, "ok"),
    RunControl(H, "start", 1700000001.0, 120.0),
]


def raw(*items: object) -> bytes:
    return bytes(msgpack.packb(list(items)))


def rec(payload: bytes, key: str = "enclose/t/follower/1/state") -> Received:
    return Received(key, payload, 0.0)


@pytest.mark.parametrize("msg", ALL_MESSAGES, ids=lambda m: type(m).__name__)
def test_round_trip_every_type(msg: Message) -> None:
    data = encode(msg)
    assert decode(data) == msg
    assert msgpack.unpackb(data)[0] == CODEC_VERSION


def test_follower_state_payload_is_compact() -> None:
    assert len(encode(follower_state())) < 200


def test_numpy_input_normalised_to_float_tuples() -> None:
    msg = follower_state(r_m=vec2(np.array([1.5, 2.5])))
    out = decode(encode(msg))
    assert isinstance(out, FollowerState)
    assert out.r_m == (1.5, 2.5) and type(out.r_m[0]) is float


def test_ints_accepted_where_floats_expected() -> None:
    data = encode(follower_state())
    obj = msgpack.unpackb(data)
    obj[5 + 1] = [1, 2]  # r_m sent as ints by some other implementation
    out = decode(msgpack.packb(obj))
    assert isinstance(out, FollowerState) and out.r_m == (1.0, 2.0)


@pytest.mark.parametrize("version", [0, CODEC_VERSION + 1, "1", True, None])
def test_version_mismatch_rejected(version: object) -> None:
    obj = msgpack.unpackb(encode(follower_state()))
    obj[0] = version
    with pytest.raises(CodecError) as err:
        decode(msgpack.packb(obj))
    assert err.value.reason == "version"


@pytest.mark.parametrize(
    "payload", [b"", b"\xc1", b"\x92\x01", b"\xff" * 3, encode(follower_state()) + b"\x00"]
)
def test_malformed_msgpack_rejected(payload: bytes) -> None:
    with pytest.raises(CodecError) as err:
        decode(payload)
    assert err.value.reason == "msgpack"


@pytest.mark.parametrize(
    ("position", "value", "reason"),
    [
        (1, 99, "unknown_type"),
        (2, 5, "type"),  # sender_id not a string
        (3, -1, "type"),  # negative seq
        (3, True, "type"),  # bool is not an int here
        (5, "one", "type"),  # index not an int
        (6, [1.0], "schema"),  # r_m of length 1
        (6, [1.0, "x"], "type"),
        (6, {"x": 1.0}, "type"),
    ],
)
def test_wrong_types_rejected(position: int, value: object, reason: str) -> None:
    obj = msgpack.unpackb(encode(follower_state()))
    obj[position] = value
    with pytest.raises(CodecError) as err:
        decode(msgpack.packb(obj))
    assert err.value.reason == reason


def test_wrong_field_count_rejected() -> None:
    obj = msgpack.unpackb(encode(follower_state()))
    for bad in (obj[:-1], [*obj, 1.0], obj[:3], {"a": 1}):
        with pytest.raises(CodecError):
            decode(msgpack.packb(bad))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_rejected_on_decode(bad: float) -> None:
    obj = msgpack.unpackb(encode(follower_state()))
    obj[6] = [0.0, bad]
    with pytest.raises(CodecError) as err:
        decode(msgpack.packb(obj))
    assert err.value.reason == "non_finite"


def test_non_finite_rejected_on_encode() -> None:
    with pytest.raises(CodecError) as err:
        encode(follower_state(u_m_s=(math.nan, 0.0)))
    assert err.value.reason == "non_finite"
    with pytest.raises(CodecError):
        encode(dataclasses.replace(follower_state(), header=Header("f", 0, math.inf)))


def test_unknown_process_state_rejected() -> None:
    with pytest.raises(CodecError):
        encode(ProcessStatus(H, "follower", 0, "sleeping"))


@pytest.mark.parametrize("version", [1, 2, 3])
def test_a_follower_state_older_than_the_law_fields_is_refused(version: int) -> None:
    """Before codec v4 a FollowerState carried the paper's law in fixed fields: no law of
    today can read it by name, so it is dropped as a version mismatch, never misread."""
    v3 = [version, 1, H.sender_id, H.seq, H.stamp_s, 1, [1.0, 2.0], [0.1, -0.2], [0.0, 0.5],
          [10.0, -20.0], [0.3, 0.4], [0.5, 0.6], 1699999999.9, [], [0.0, 0.0], []]
    with pytest.raises(CodecError) as err:
        decode(bytes(msgpack.packb(v3[:{1: 13, 2: 14, 3: 16}[version]])))
    assert err.value.reason == "version"
    older = RunControl(H, "start", 1.0, 2.0)  # other types of older versions still read
    payload = msgpack.unpackb(encode(older))
    payload[0] = 1
    assert decode(bytes(msgpack.packb(payload))) == older


@pytest.mark.parametrize(
    ("law", "reason"),
    [({"x": [0.0]}, "schema"), ({"x": [0.0, float("inf")]}, "non_finite"),
     ({"x": [0.0, None]}, "type"), ({"x": None}, "type"), ({"x": True}, "type"),
     ({"x": [[0, 1.0]]}, "schema"), ({"x": [[-1, 1.0, 2.0]]}, "type"),
     ({"x": [[0, 1.0, float("nan")]]}, "non_finite"), ({"x": [[True, 1.0, 2.0]]}, "type"),
     ({"": 1.0}, "type"), ({"x" * 65: 1.0}, "type"), ([1.0], "type"),
     ({f"f{k}": 1.0 for k in range(17)}, "type"), ({"x": [[0, 1.0, 2.0]] * 257}, "type")],
)
def test_malformed_law_fields_rejected(law: object, reason: str) -> None:
    payload = msgpack.unpackb(encode(follower_state()))
    payload[-1] = law
    with pytest.raises(CodecError) as err:
        decode(bytes(msgpack.packb(payload)))
    assert err.value.reason == reason


def test_unknown_run_command_rejected() -> None:
    with pytest.raises(CodecError):
        encode(RunControl(H, "pause", 0.0, 1.0))


def test_too_large_payload_rejected() -> None:
    with pytest.raises(CodecError) as err:
        decode(b"\x00" * (codec.MAX_PAYLOAD_BYTES + 1))
    assert err.value.reason == "too_large"


def test_decoder_drops_and_counts_per_reason() -> None:
    good = encode(follower_state())
    obj = msgpack.unpackb(good)
    obj[6] = [math.nan, 0.0]
    nan_payload = bytes(msgpack.packb(obj))
    decoder = Decoder()
    out = decoder.decode_all(
        [rec(b"\xc1"), rec(good), rec(nan_payload), rec(nan_payload), rec(raw(99, 1, "x", 0, 0.0))]
    )
    assert [i.message for i in out] == [follower_state()]
    assert decoder.dropped == {"msgpack": 1, "non_finite": 2, "version": 1}
    assert decoder.counters()["drop_non_finite"] == 2 and decoder.accepted == 1


def test_decoder_checks_expected_type_and_key_index() -> None:
    decoder = Decoder(expect=(FollowerState,))
    status = encode(ProcessStatus(H, "sim", 0, "running"))
    assert decoder.decode(rec(status)) is None
    assert decoder.decode(rec(encode(follower_state()), key="enclose/t/follower/2/state")) is None
    assert decoder.dropped == {"unexpected_type": 1, "key_mismatch": 1}


def test_decoder_counts_gaps_and_stale_per_sender() -> None:
    stamper = Stamper("follower-1", clock=lambda: 5.0)
    msgs = [follower_state(header=stamper.header()) for _ in range(6)]
    order = [0, 1, 4, 3, 4, 5]  # 2 and 3 late: 2 never arrives, 3 arrives stale, 4 duplicated
    decoder = Decoder()
    out = decoder.decode_all([rec(encode(msgs[k])) for k in order])
    assert [i.stale for i in out] == [False, False, False, True, True, False]
    assert decoder.gaps["follower-1"] == 2 and decoder.stale["follower-1"] == 2


def test_stamper_increments_seq_and_uses_clock() -> None:
    times = iter([1.0, 2.0])
    stamper = Stamper("sim-0", clock=lambda: next(times))
    assert stamper.header() == Header("sim-0", 0, 1.0)
    assert stamper.header() == Header("sim-0", 1, 2.0)
    assert stamper.header(stamp_s=9.0) == Header("sim-0", 2, 9.0)


def test_newer_field_defaults_when_decoding_older_version(monkeypatch: pytest.MonkeyPatch) -> None:
    """A version bump appends a field with a default; older payloads still decode."""
    tag, fields = codec.SCHEMAS[TargetObservation]
    bumped_version = CODEC_VERSION + 1
    bumped = (*fields[:-1], codec.Field("noise_std_m", "opt_float", since=bumped_version))
    monkeypatch.setitem(codec.SCHEMAS, TargetObservation, (tag, bumped))
    monkeypatch.setitem(codec._BY_TAG, tag, (TargetObservation, bumped))
    monkeypatch.setattr(codec, "CODEC_VERSION", bumped_version)
    old = raw(CODEC_VERSION, tag, "sim-0", 3, 1.0, 0, 1, [1.0, 2.0], 0.5)
    out = decode(old)
    assert isinstance(out, TargetObservation) and out.noise_std_m is None
    assert decode(encode(ALL_MESSAGES[1])) == ALL_MESSAGES[1]


def test_decoder_tracks_streams_per_key() -> None:
    """One sender numbering two keys separately is not a gap."""
    decoder = Decoder()
    for key_index in (1, 2):
        stamper = Stamper("sim-0", clock=lambda: 0.0)
        for _ in range(3):
            obs = TargetObservation(stamper.header(), key_index, 0, (1.0, 1.0), 0.0)
            assert decoder.decode(rec(encode(obs), key=f"enclose/t/sensor/{key_index}/targets"))
    assert decoder.gaps["sim-0"] == 0 and decoder.stale["sim-0"] == 0
