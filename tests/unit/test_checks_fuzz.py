"""Messages checked, not trusted (transport.message_checks), and the codec under random input."""

from __future__ import annotations

import math

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from errors import CodecError
from transport.bus import Received
from transport.codec import decode, encode
from transport.decoder import Decoder
from transport.key_exprs import SwarmKeys
from transport.law_fields import FieldSpec
from transport.law_fields import reason as law_reason
from transport.message_checks import DEFAULT_LIMITS, check, newer
from transport.messages import FollowerState, Header, RunControl, TargetObservation

KEYS = SwarmKeys("chk")
NOW = 1_800_000_000.0


def state(i: int = 1, sender: str | None = None, stamp: float = NOW, **kw: object) -> FollowerState:
    fields: dict[str, object] = dict(r_m=(1.0, 2.0), dr_m_s=(0.1, 0.0),
                                     pos_m=(3.0, 4.0), vel_m_s=(1.0, 1.0), u_m_s=(1.0, 0.0),
                                     vehicle_stamp_s=stamp - 0.01, law={"phi_m": (0.5, 0.5)})
    fields.update(kw)
    return FollowerState(Header(sender or f"follower-{i}", 0, stamp), i, **fields)  # type: ignore[arg-type]


def test_plausible_state_passes_and_each_fault_is_named() -> None:
    key = KEYS.follower_state(1)
    assert check(state(), key, NOW) is None
    assert check(state(sender="follower-2"), key, NOW) == "sender"
    assert check(state(stamp=NOW + 5.0), key, NOW) == "future_stamp"
    assert check(state(stamp=NOW - 3600.0), key, NOW) == "old_stamp"
    assert check(state(r_m=(math.nan, 0.0)), key, NOW) == "nonfinite"
    assert check(state(pos_m=(1e7, 0.0)), key, NOW) == "impossible"
    assert check(state(vel_m_s=(0.0, 5e3)), key, NOW) == "impossible"
    with pytest.raises(CodecError):  # a law's fields: finite on the wire, by the codec
        encode(state(law={"s": ((0, 1.0, math.inf),)}))
    ctl = RunControl(Header("follower-1", 0, NOW), "stop", NOW, 0.0)
    assert check(ctl, KEYS.control(), NOW) == "sender"
    obs = TargetObservation(Header("sim-0", 0, NOW), 1, 0, (1e9, 0.0), NOW)
    assert check(obs, KEYS.sensor_targets(1), NOW) == "impossible"


def test_law_fields_checked_against_the_declaration() -> None:
    """A receiver that knows the law drops a state whose fields are not the declared ones:
    an undeclared name, the wrong kind, a value beyond its bound; each counted by reason."""
    key = KEYS.follower_state(1)
    specs = {"rv_m_s": FieldSpec("rv_m_s", "vec2", 1e3),
             "sums": FieldSpec("sums", "per_link", 1e5, rate="rates"),
             "rates": FieldSpec("rates", "per_link", 1e4), "gain": FieldSpec("gain", "scalar", 1.0)}
    fine = state(law={"rv_m_s": (0.5, -0.5), "sums": ((0, 0.25, 0.0),), "rates": (),
                      "gain": -1.0})
    bad = {"law_undeclared": state(law={"phi_m": (0.0, 0.0)}),
           "law_kind": state(law={"gain": (1.0, 0.0)}),
           "law_bound": state(law={"rates": ((0, 0.0, 1.5e4),)})}
    dec = Decoder(limits=DEFAULT_LIMITS, law_fields=specs)
    for msg in (fine, *bad.values()):
        dec.decode(Received(key, encode(msg), NOW))
    assert dec.accepted == 1
    assert dec.dropped == {f"rejected_{why}": 1 for why in bad}
    assert all(law_reason(m.law, specs) == why for why, m in bad.items())
    lax = Decoder(limits=DEFAULT_LIMITS)  # a receiver that knows no law: structure only
    assert all(lax.decode(Received(key, encode(m), NOW)) for m in bad.values())


def test_one_future_stamped_state_cannot_freeze_the_view() -> None:
    kept = NOW + 0.4  # accepted (within the tolerance), then the next real one replaces it
    assert newer(NOW + 0.02, kept, now_s=NOW + 0.02)
    assert not newer(NOW - 1.0, NOW, now_s=NOW)  # an older one never replaces a current one


def test_decoder_with_limits_drops_and_counts() -> None:
    dec = Decoder(limits=DEFAULT_LIMITS)
    key = KEYS.follower_state(1)
    for msg in (state(), state(stamp=NOW + 100.0), state(sender="rogue")):
        dec.decode(Received(key, encode(msg), NOW))
    assert dec.accepted == 1
    assert dec.dropped["rejected_future_stamp"] == 1 and dec.dropped["rejected_sender"] == 1


finite = st.floats(-1e6, 1e6, allow_nan=False)
anyfloat = st.floats(allow_nan=True, allow_infinity=True)
vec = st.tuples(anyfloat, anyfloat)


@settings(max_examples=300, deadline=None)
@given(vec, vec, vec, vec, anyfloat, anyfloat)
def test_check_never_raises_and_refuses_every_nonfinite(r: tuple[float, float],
                                                        dr: tuple[float, float],
                                                        pos: tuple[float, float],
                                                        vel: tuple[float, float],
                                                        stamp: float, vstamp: float) -> None:
    msg = state(r_m=r, dr_m_s=dr, pos_m=pos, vel_m_s=vel, vehicle_stamp_s=vstamp)
    msg = FollowerState(Header("follower-1", 0, stamp), *[getattr(msg, f) for f in (
        "index", "r_m", "dr_m_s", "pos_m", "vel_m_s", "u_m_s", "vehicle_stamp_s", "law")])
    verdict = check(msg, KEYS.follower_state(1), NOW)
    numbers = [*r, *dr, *pos, *vel, stamp, vstamp]
    if not all(math.isfinite(x) for x in numbers):
        assert verdict is not None


@settings(max_examples=300, deadline=None)
@given(finite, finite, st.integers(0, 2**31), finite)
def test_codec_round_trips_any_finite_state(x: float, y: float, seq: int, stamp: float) -> None:
    msg = FollowerState(Header("follower-3", seq, stamp), 3, (x, y), (y, x), (y, y),
                        (0.0, x), (y, 0.0), stamp,
                        {"phi_m": (x, x), "s": ((1, x, y), (2, y, x)), "k": y})
    assert decode(encode(msg)) == msg


@settings(max_examples=500, deadline=None)
@given(st.binary(max_size=512))
def test_codec_random_bytes_raise_only_codec_error(payload: bytes) -> None:
    try:
        decode(payload)
    except CodecError as exc:
        assert exc.reason


json_like = st.recursive(
    st.none() | st.booleans() | st.integers(-2**63, 2**64 - 1) | anyfloat | st.text(max_size=8)
    | st.binary(max_size=8),
    lambda inner: st.lists(inner, max_size=8), max_leaves=40)


@settings(max_examples=500, deadline=None)
@given(st.lists(json_like, max_size=16), st.integers(0, 15), json_like)
def test_codec_mutated_messages_raise_only_codec_error(items: list, pos: int,
                                                       value: object) -> None:
    good = msgpack.unpackb(encode(state()))
    mutated = list(good)
    mutated[pos % len(mutated)] = value
    for payload in (msgpack.packb(items), msgpack.packb(mutated), msgpack.packb(good + items)):
        try:
            msg = decode(payload)
        except CodecError:
            continue
        assert check(msg, KEYS.follower_state(1), NOW) in (None, "sender", "future_stamp",
                                                             "old_stamp", "nonfinite",
                                                             "impossible")
