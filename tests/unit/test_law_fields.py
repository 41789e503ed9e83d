"""A law's declared fields on the wire (transport.law_fields, codec v4) under hostile input:
NaN and infinities, huge counts, undeclared names, wrong types and shapes.  A receiver
never raises: it keeps a state whose fields are all declared, of their kinds, finite and
within their bounds, and drops and counts every other."""

from __future__ import annotations

import math
from typing import Any

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from errors import CodecError
from transport.bus import Received
from transport.codec import decode, encode
from transport.decoder import Decoder
from transport.key_exprs import SwarmKeys
from transport.law_fields import MAX_FIELDS, MAX_LINKS, FieldSpec, check_specs, reason
from transport.message_checks import DEFAULT_LIMITS
from transport.messages import FollowerState, Header

KEYS = SwarmKeys("lf")
NOW = 1_800_000_000.0
SPECS = check_specs([FieldSpec("phi_m", "vec2", 1e5), FieldSpec("gain", "scalar", 10.0),
                     FieldSpec("sums", "per_link", 1e5, rate="rates"),
                     FieldSpec("rates", "per_link", 1e3)])
pytestmark = pytest.mark.timeout(120)


def state(law: Any) -> FollowerState:
    return FollowerState(Header("follower-1", 0, NOW), 1, (1.0, 2.0), (0.0, 0.0), (3.0, 4.0),
                         (0.0, 0.0), (0.0, 0.0), NOW, law)


def wire_with(law: Any) -> bytes:
    """A valid FollowerState's payload with `law` put where its fields go."""
    obj = msgpack.unpackb(encode(state({})))
    obj[-1] = law
    return bytes(msgpack.packb(obj))


def accepted(payload: bytes) -> FollowerState | None:
    dec = Decoder(limits=DEFAULT_LIMITS, law_fields=SPECS)
    inbound = dec.decode(Received(KEYS.follower_state(1), payload, NOW))
    assert dec.accepted + sum(dec.dropped.values()) == 1  # one verdict, counted
    return None if inbound is None else inbound.message  # type: ignore[return-value]


def well_formed(msg: FollowerState) -> bool:
    """Declared names only, each of its declared kind, finite and within its bound."""
    for name, value in msg.law.items():
        spec = SPECS.get(name)
        if spec is None:
            return False
        if spec.kind == "scalar":
            ok = type(value) is float and abs(value) <= spec.bound
        elif spec.kind == "vec2":
            ok = (type(value) is tuple and len(value) == 2 and all(type(v) is float for v in value)
                  and math.hypot(*value) <= spec.bound)
        else:
            ok = type(value) is tuple and len(value) <= MAX_LINKS and all(
                type(e) is tuple and len(e) == 3 and type(e[0]) is int and e[0] >= 0
                and math.hypot(e[1], e[2]) <= spec.bound for e in value)
        if not ok:
            return False
    return True


number = st.floats() | st.integers(-2**63, 2**64 - 1) | st.booleans() | st.sampled_from(
    [math.nan, math.inf, -math.inf, 1e308, 1e5, 1e5 + 1.0, 10.0, 10.5])
hostile_value = st.recursive(
    number | st.none() | st.text(max_size=3) | st.binary(max_size=3),
    lambda inner: st.lists(inner, max_size=5), max_leaves=12)
link = st.lists(number, min_size=3, max_size=3) | st.lists(number, max_size=4)
name = st.sampled_from(["phi_m", "gain", "sums", "rates", "secret", "", "x" * 65]) | st.text(
    max_size=4)
value = (number | st.lists(number, min_size=2, max_size=2) | st.lists(link, max_size=4)
         | st.lists(link, min_size=257, max_size=258) | hostile_value)
hostile_law = (st.dictionaries(name, value, max_size=5)
               | st.dictionaries(st.text(min_size=1, max_size=3), st.just(1.0),
                                 min_size=MAX_FIELDS + 1, max_size=MAX_FIELDS + 2)
               | hostile_value)


@settings(max_examples=600, deadline=None)
@given(hostile_law)
def test_hostile_law_fields_never_raise_and_only_declared_ones_get_in(law: Any) -> None:
    payload = wire_with(law)
    try:
        decode(payload)
    except CodecError as exc:
        assert exc.reason in ("type", "schema", "non_finite")
    msg = accepted(payload)
    assert msg is None or well_formed(msg)


finite = st.floats(-700.0, 700.0, allow_nan=False)  # |(x, y)| within every bound
declared = st.fixed_dictionaries({}, optional={
    "phi_m": st.tuples(finite, finite), "gain": st.floats(-10.0, 10.0),
    "sums": st.lists(st.tuples(st.integers(0, 64), finite, finite), max_size=4).map(tuple),
    "rates": st.lists(st.tuples(st.integers(0, 64), finite, finite), max_size=4).map(tuple)})


@settings(max_examples=300, deadline=None)
@given(declared)
def test_declared_fields_round_trip_and_are_kept(law: dict[str, Any]) -> None:
    msg = state(law)
    assert decode(encode(msg)) == msg
    assert accepted(encode(msg)) == msg and reason(law, SPECS) is None


@pytest.mark.parametrize(("law", "why"), [
    ({"secret": 1.0}, "law_undeclared"), ({"gain": (1.0, 2.0)}, "law_kind"),
    ({"phi_m": 1.0}, "law_kind"), ({"sums": (1.0, 2.0)}, "law_kind"),
    ({"gain": 10.5}, "law_bound"), ({"rates": ((0, 1e3, 1.0),)}, "law_bound"),
    ({"gain": math.nan}, "law_kind"), ({"phi_m": (math.inf, 0.0)}, "law_kind"),
])
def test_each_refusal_is_named(law: dict[str, Any], why: str) -> None:
    assert reason(law, SPECS) == why
    dec = Decoder(limits=DEFAULT_LIMITS, law_fields=SPECS)
    if all(math.isfinite(x) for v in law.values() for x in _numbers(v)):
        dec.decode(Received(KEYS.follower_state(1), encode(state(law)), NOW))
        assert dec.dropped == {f"rejected_{why}": 1}


def _numbers(v: Any) -> list[float]:
    if isinstance(v, tuple):
        return [x for item in v for x in _numbers(item)]
    return [v] if isinstance(v, float) else []


def test_a_declaration_is_checked() -> None:
    with pytest.raises(ValueError, match="kind"):
        FieldSpec("x", "matrix", 1.0)
    with pytest.raises(ValueError, match="bound"):
        FieldSpec("x", "scalar", math.inf)
    with pytest.raises(ValueError, match="identifier"):
        FieldSpec("not a name", "scalar", 1.0)
    with pytest.raises(ValueError, match="twice"):
        check_specs([FieldSpec("x", "scalar", 1.0)] * 2)
    with pytest.raises(ValueError, match="rate"):
        check_specs([FieldSpec("x", "scalar", 1.0, rate="y")])
    with pytest.raises(ValueError, match="rate"):
        check_specs([FieldSpec("x", "scalar", 1.0, rate="y"), FieldSpec("y", "vec2", 1.0)])
    with pytest.raises(ValueError, match="at most"):
        check_specs([FieldSpec(f"f{k}", "scalar", 1.0) for k in range(MAX_FIELDS + 1)])
