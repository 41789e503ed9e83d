"""msgpack codec with a version field and an explicit schema per message type.

Wire format: one msgpack array
    [version, type_tag, sender_id, seq, stamp_s, field_1, field_2, ...]
with the fields of the message type in schema order.  A field has a kind
(checked on encode *and* decode: type, length, finiteness) and the codec
version that introduced it; a version bump may only append fields that have
defaults, so a newer decoder still reads older payloads.

`encode` / `decode` raise `CodecError` (with a `reason`).  Processes use a
`Decoder`, which never raises: it drops bad payloads and counts them per reason,
and counts per-sender sequence gaps and stale (duplicate/reordered) messages.

The schema walk below is the reference.  `encode` / `decode` first try the message
type's fast twin (transport.codec_fast: straight-line code, several times cheaper), which
only ever accepts what the reference accepts, with the same result; whatever a twin does
not take (any bad input, older versions, unusual types) goes through the reference, so
every error and its reason come from one place.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any

import msgpack

from errors import CodecError
from transport import codec_fast
from transport.law_fields import MAX_FIELDS, MAX_LINKS, MAX_NAME, LawValue
from transport.messages import (
    PROCESS_STATES,
    RUN_COMMANDS,
    ClockProbe,
    FollowerState,
    Header,
    Message,
    ProcessStatus,
    RunControl,
    TargetObservation,
    TruthSnapshot,
)

# 2: FollowerState.link_flows (robust estimator); 3: its rv_m_s, rv_flows (second order);
# 4: the law's fields in FollowerState.law, in place of its paper-law fields
CODEC_VERSION = 4
MIN_VERSION = 1
MAX_PAYLOAD_BYTES = 1 << 16
_MAX_ITEMS = 256  # longest list/map accepted (vehicles in a snapshot, counters)
_HEADER_LEN = 5


@dataclass(frozen=True)
class Field:
    name: str
    kind: str  # int float opt_float str state command vec2 vec2s vec3s counters echoes law
    since: int = 1


SCHEMAS: dict[type, tuple[int, tuple[Field, ...]]] = {
    FollowerState: (1, (
        Field("index", "int"), Field("r_m", "vec2"), Field("dr_m_s", "vec2"),
        Field("pos_m", "vec2"), Field("vel_m_s", "vec2"), Field("u_m_s", "vec2"),
        Field("vehicle_stamp_s", "float"), Field("law", "law", since=4),
    )),
    TargetObservation: (2, (
        Field("observer_index", "int"), Field("target_index", "int"), Field("pos_m", "vec2"),
        Field("observed_stamp_s", "float"), Field("noise_std_m", "opt_float"),
    )),
    TruthSnapshot: (3, (
        Field("sim_time_s", "float"), Field("follower_pos_m", "vec3s"),
        Field("follower_vel_m_s", "vec3s"), Field("target_pos_m", "vec2s"),
        Field("target_vel_m_s", "vec2s"),
    )),
    ProcessStatus: (4, (
        Field("role", "str"), Field("index", "int"), Field("state", "state"),
        Field("counters", "counters"), Field("detail", "str"),
    )),
    RunControl: (5, (
        Field("command", "command"), Field("start_stamp_s", "float"),
        Field("duration_s", "float"),
    )),
    ClockProbe: (6, (Field("epoch_s", "float"), Field("echoes", "echoes"))),
}
_BY_TAG = {tag: (cls, fields) for cls, (tag, fields) in SCHEMAS.items()}
# A type whose earlier fields were removed: its older payloads are refused ("version").
# FollowerState before 4 carried the paper's law in fixed fields.
_SINCE = {1: 4}


def _fail(reason: str, detail: str) -> CodecError:
    return CodecError(f"{reason}: {detail}", reason=reason)


def _float(v: Any, name: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise _fail("type", f"{name} must be a number, got {type(v).__name__}")
    f = float(v)
    if not math.isfinite(f):
        raise _fail("non_finite", f"{name} = {v}")
    return f


def _int(v: Any, name: str) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v < 0:
        raise _fail("type", f"{name} must be a non-negative int, got {v!r}")
    return v


def _str(v: Any, name: str) -> str:
    if not isinstance(v, str) or len(v) > 256:
        raise _fail("type", f"{name} must be a string of <= 256 characters")
    return v


def _seq(v: Any, name: str, length: int | None = None) -> list[Any] | tuple[Any, ...]:
    if not isinstance(v, list | tuple) or len(v) > _MAX_ITEMS:
        raise _fail("type", f"{name} must be a list")
    if length is not None and len(v) != length:
        raise _fail("schema", f"{name} must have {length} items, got {len(v)}")
    return v


def _vec(v: Any, name: str, dim: int) -> tuple[float, ...]:
    return tuple(_float(x, name) for x in _seq(v, name, dim))


def _law(v: Any, name: str) -> dict[str, LawValue]:
    """A law's fields (transport.law_fields): a map of <= MAX_FIELDS names to a float, a
    pair of floats, or a list of <= MAX_LINKS (neighbour, x, y)."""
    if not isinstance(v, dict) or len(v) > MAX_FIELDS:
        raise _fail("type", f"{name} must be a map of <= {MAX_FIELDS} fields")
    out: dict[str, LawValue] = {}
    for key, value in v.items():
        if not isinstance(key, str) or not 0 < len(key) <= MAX_NAME:
            raise _fail("type", f"{name}: a field name must be a string of <= {MAX_NAME}")
        where = f"{name}.{key}"
        if isinstance(value, list | tuple) and value and not isinstance(value[0], list | tuple):
            out[key] = (_float(_seq(value, where, 2)[0], where), _float(value[1], where))
        elif isinstance(value, list | tuple):
            if len(value) > MAX_LINKS:
                raise _fail("type", f"{where}: more than {MAX_LINKS} links")
            out[key] = tuple(_link(x, where) for x in value)
        else:
            out[key] = _float(value, where)
    return out


def _link(v: Any, name: str) -> tuple[int, float, float]:
    j, x, y = _seq(v, name, 3)
    return (_int(j, name), _float(x, name), _float(y, name))


def _echo(v: Any, name: str) -> tuple[str, float, float]:
    peer, t1, t2 = _seq(v, name, 3)
    return (_str(peer, name), _float(t1, name), _float(t2, name))


def _counters(v: Any, name: str) -> dict[str, int]:
    if not isinstance(v, dict) or len(v) > _MAX_ITEMS:
        raise _fail("type", f"{name} must be a map")
    out: dict[str, int] = {}
    for k, n in v.items():
        if isinstance(n, bool) or not isinstance(n, int):
            raise _fail("type", f"{name}[{k!r}] must be an int")
        out[_str(k, name)] = n
    return out


def _check(kind: str, v: Any, name: str) -> Any:
    """The validated, normalised value of one field (same rules both ways)."""
    if kind == "float":
        return _float(v, name)
    if kind == "opt_float":
        return None if v is None else _float(v, name)
    if kind == "int":
        return _int(v, name)
    if kind == "str":
        return _str(v, name)
    if kind in ("state", "command"):
        allowed = PROCESS_STATES if kind == "state" else RUN_COMMANDS
        if v not in allowed:
            raise _fail("schema", f"{name} = {v!r} not in {allowed}")
        return v
    if kind == "vec2":
        return _vec(v, name, 2)
    if kind in ("vec2s", "vec3s"):
        dim = 2 if kind == "vec2s" else 3
        return tuple(_vec(x, name, dim) for x in _seq(v, name))
    if kind == "counters":
        return _counters(v, name)
    if kind == "law":
        return _law(v, name)
    if kind == "echoes":
        return tuple(_echo(x, name) for x in _seq(v, name))
    raise AssertionError(f"unknown field kind {kind}")


def _wire(kind: str, v: Any) -> Any:
    if kind == "law":
        return dict(v)  # msgpack packs a tuple as it does a list
    if kind in ("vec2", "vec2s", "vec3s", "echoes"):
        return [list(x) for x in v] if kind != "vec2" else list(v)
    return v


class _Packers(threading.local):
    """A msgpack Packer per thread (clock sync encodes on its own): half the cost of packb."""

    def __init__(self) -> None:
        self.pack = msgpack.Packer(use_bin_type=True).pack


_PACKERS = _Packers()


def signature(fields: tuple[Field, ...]) -> str:
    """A schema's fields as codec_fast.TWINS spells them."""
    return " ".join(f"{f.name}:{f.kind}" + (f"@{f.since}" if f.since > 1 else "") for f in fields)


_Decoders = dict[int, tuple[int, codec_fast.Decoder]]


def _fast_twins() -> tuple[dict[type, codec_fast.Encoder], _Decoders]:
    """The fast twins whose schema is still exactly the one in SCHEMAS."""
    encoders: dict[type, codec_fast.Encoder] = {}
    decoders: _Decoders = {}
    if CODEC_VERSION != codec_fast.VERSION:
        return encoders, decoders
    for cls, (twin_tag, twin_fields, enc, dec) in codec_fast.TWINS.items():
        tag, fields = SCHEMAS[cls]
        if (tag, signature(fields)) == (twin_tag, twin_fields):
            encoders[cls] = enc
            decoders[tag] = (_HEADER_LEN + len(fields), dec)
    return encoders, decoders


FAST_ENCODERS, FAST_DECODERS = _fast_twins()


def encode(msg: Message) -> bytes:
    """msgpack bytes of `msg`; CodecError if a field is invalid (e.g. NaN)."""
    twin = FAST_ENCODERS.get(type(msg))
    if twin is not None:
        try:
            wire = twin(msg)
        except (TypeError, ValueError):  # a wrong length or type: the reference says which
            wire = None
        if wire is not None:
            return bytes(_PACKERS.pack(wire))
    return encode_reference(msg)


def decode(payload: bytes) -> Message:
    """The message in `payload`; CodecError (with `.reason`) if anything is wrong."""
    obj = _unpack(payload)
    version, tag = obj[0], obj[1]
    if type(version) is int and version == CODEC_VERSION and type(tag) is int:
        twin = FAST_DECODERS.get(tag)
        if twin is not None and len(obj) == twin[0]:
            try:
                msg = twin[1](obj)
            except (TypeError, ValueError):
                msg = None
            if msg is not None:
                return msg
    return _decode_walk(obj)


def encode_reference(msg: Message) -> bytes:
    """`encode` by the schema walk alone (the reference the fast twins are pinned to)."""
    try:
        tag, fields = SCHEMAS[type(msg)]
    except KeyError:
        raise _fail("type", f"{type(msg).__name__} is not a message type") from None
    h = msg.header
    head = [CODEC_VERSION, tag, _str(h.sender_id, "sender_id"), _int(h.seq, "seq"),
            _float(h.stamp_s, "stamp_s")]
    body = [_wire(f.kind, _check(f.kind, getattr(msg, f.name), f.name)) for f in fields]
    return bytes(msgpack.packb(head + body, use_bin_type=True))


def decode_reference(payload: bytes) -> Message:
    """`decode` by the schema walk alone (the reference the fast twins are pinned to)."""
    return _decode_walk(_unpack(payload))


def _unpack(payload: bytes) -> list[Any]:
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise _fail("too_large", f"{len(payload)} bytes")
    try:
        obj = msgpack.unpackb(payload, raw=False, strict_map_key=True, use_list=True)
    except Exception as exc:  # hostile input: msgpack raises many unrelated types
        raise _fail("msgpack", f"{type(exc).__name__}: {exc}") from None
    if not isinstance(obj, list) or len(obj) < _HEADER_LEN:
        raise _fail("schema", "payload is not a message array")
    return obj


def _decode_walk(obj: list[Any]) -> Message:
    version, tag = obj[0], obj[1]
    if isinstance(version, bool) or not isinstance(version, int):
        raise _fail("version", f"version {version!r} is not an int")
    if not MIN_VERSION <= version <= CODEC_VERSION:
        raise _fail("version", f"version {version} not in [{MIN_VERSION}, {CODEC_VERSION}]")
    # A list or map as tag is unhashable: `in` would raise TypeError (found by fuzzing).
    if isinstance(tag, bool) or not isinstance(tag, int | str) or tag not in _BY_TAG:
        raise _fail("unknown_type", f"type tag {tag!r}")
    cls, fields = _BY_TAG[tag]
    if version < _SINCE.get(tag, MIN_VERSION):
        raise _fail("version", f"{cls.__name__} v{version} is older than v{_SINCE[tag]}")
    present = [f for f in fields if f.since <= version]
    if len(obj) != _HEADER_LEN + len(present):
        raise _fail("schema", f"{cls.__name__} v{version} needs {len(present)} fields")
    header = Header(_str(obj[2], "sender_id"), _int(obj[3], "seq"), _float(obj[4], "stamp_s"))
    body = zip(present, obj[_HEADER_LEN:], strict=True)
    values = {f.name: _check(f.kind, v, f.name) for f, v in body}
    try:
        msg: Message = cls(header=header, **values)
    except TypeError as exc:  # a field added later lacks a default: a schema bug, not input
        raise _fail("schema", str(exc)) from None
    return msg
