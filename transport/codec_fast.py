"""Fast twins of the codec's schema walk, one straight-line function per message type.

The reference codec (transport.codec) walks a message's schema field by field, through
a generic check per field kind: ~50 µs for a FollowerState, most of a follower's CPU at
50-200 Hz (issue 15).  The twins here do the same work for one message type each, for
the common case only: the current codec version, exact types (float, int, str; tuples
on encode, lists on decode), every number finite.  Anything else -- an int where a float
is expected, a bool, a NaN, a wrong length, an older version, a numpy scalar -- makes a
twin give up (return None, or raise ValueError/TypeError while unpacking), and the codec
falls back to the reference, which then accepts it or names the reason.  A twin never
rejects anything itself: it can only accept what the reference accepts, with an equal
result (tests/unit/test_codec_fast.py pins both ways, on valid and hostile input).

Finiteness without a call per number: the sum of a message's floats is finite when every
one is (a NaN or an infinity makes it NaN or infinite, and then `s - s` is NaN, not 0.0);
a sum that overflowed from finite terms only sends the message to the reference.

Decoded messages are built without their dataclass `__init__` (transport.fastbuild).

Each twin is written for one schema: `TWINS` below says which, and the codec uses a twin
only while SCHEMAS still says exactly that (and CODEC_VERSION is `VERSION`); a schema
change without a new twin is slow, never wrong.  Only the messages sent at the control
rate have a twin: for the low-rate ones (ProcessStatus at 1 Hz, ClockProbe at 4 Hz per
host, RunControl twice a run) the schema walk costs a few µs a second
(`python bench/bench_codec.py`: its "walk" columns).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from transport.fastbuild import NEW, SET
from transport.law_fields import MAX_FIELDS, MAX_LINKS, MAX_NAME, LawValue
from transport.messages import (
    FollowerState,
    Header,
    Message,
    TargetObservation,
    TruthSnapshot,
)

VERSION = 4  # the codec version the twins write and read
MAX_STR = 256
MAX_ITEMS = 256
_NAN = float("nan")
Wire = list[Any]
Encoder = Callable[[Any], Wire | None]
Decoder = Callable[[Wire], Message | None]
# On decode, a container is checked by what comes out of it: of the values msgpack makes
# (None, bool, int, float, str, bytes, list, map with str/bytes keys, ExtType, Timestamp),
# only a list unpacks into floats.


def header(sid: str, seq: int, stamp_s: float) -> Header:
    h = NEW(Header)
    SET(h, "__dict__", {"sender_id": sid, "seq": seq, "stamp_s": stamp_s})
    return h


def head_ok(sid: Any, seq: Any, stamp_s: Any) -> bool:
    return (type(sid) is str and len(sid) <= MAX_STR and type(seq) is int and seq >= 0
            and type(stamp_s) is float)


def _vec2s_sum(vecs: Any, seq_type: Any) -> float:
    """Sum of the numbers of a `seq_type` of <= MAX_ITEMS `seq_type`s of 2 exact floats;
    NaN if `vecs` is not one."""
    if type(vecs) is not seq_type or len(vecs) > MAX_ITEMS:
        return _NAN
    s = 0.0
    for v in vecs:
        if type(v) is not seq_type:
            return _NAN
        x, y = v
        if type(x) is not float or type(y) is not float:
            return _NAN
        s += x + y
    return s


def _vec3s_sum(vecs: Any, seq_type: Any) -> float:
    """As _vec2s_sum, for 3-vectors."""
    if type(vecs) is not seq_type or len(vecs) > MAX_ITEMS:
        return _NAN
    s = 0.0
    for v in vecs:
        if type(v) is not seq_type:
            return _NAN
        x, y, z = v
        if type(x) is not float or type(y) is not float or type(z) is not float:
            return _NAN
        s += x + y + z
    return s


def _law_sum(law: Any, seq_type: Any) -> float:
    """Sum of the numbers of a law's fields (transport.law_fields), given as a dict of
    <= MAX_FIELDS str keys to an exact float, a `seq_type` of 2 exact floats, or a
    `seq_type` of <= MAX_LINKS `seq_type`s of a non-negative int and 2 exact floats; NaN
    if it is not one."""
    if type(law) is not dict or len(law) > MAX_FIELDS:
        return _NAN
    s = 0.0
    for key, value in law.items():
        if type(key) is not str or not 0 < len(key) <= MAX_NAME:
            return _NAN
        if type(value) is float:
            s += value
        elif type(value) is not seq_type or len(value) > MAX_LINKS:
            return _NAN
        elif value and type(value[0]) is float:
            x, y = value
            if type(y) is not float:
                return _NAN
            s += x + y
        else:
            for link in value:
                if type(link) is not seq_type:
                    return _NAN
                j, x, y = link
                if not (type(j) is int and j >= 0 and type(x) is float and type(y) is float):
                    return _NAN
                s += x + y
    return s


def _law_in(law: Any) -> dict[str, LawValue] | None:
    """A decoded law map (transport.law_fields) with its lists as tuples, checked as
    _law_sum checks it, in one pass; None if it is not one."""
    if type(law) is not dict or len(law) > MAX_FIELDS:
        return None
    out: dict[str, LawValue] = {}
    s = 0.0
    for key, value in law.items():
        if type(key) is not str or not 0 < len(key) <= MAX_NAME:
            return None
        if type(value) is float:
            s += value
            out[key] = value
        elif type(value) is not list or len(value) > MAX_LINKS:
            return None
        elif value and type(value[0]) is float:
            x, y = value
            if type(y) is not float:
                return None
            s += x + y
            out[key] = (x, y)
        else:
            links = []
            for j, x, y in value:
                if not (type(j) is int and j >= 0 and type(x) is float and type(y) is float):
                    return None
                s += x + y
                links.append((j, x, y))
            out[key] = tuple(links)
    return out if s - s == 0.0 else None


# ---- FollowerState, TargetObservation, TruthSnapshot: 50-200 Hz -----------------------------
def enc_follower_state(m: FollowerState) -> Wire | None:
    h = m.header
    sid, seq, st, idx, vst = h.sender_id, h.seq, h.stamp_s, m.index, m.vehicle_stamp_s
    r, dr, pos, vel, u, law = m.r_m, m.dr_m_s, m.pos_m, m.vel_m_s, m.u_m_s, m.law
    if not (head_ok(sid, seq, st) and type(idx) is int and idx >= 0 and type(vst) is float
            and type(r) is tuple and type(dr) is tuple and type(pos) is tuple
            and type(vel) is tuple and type(u) is tuple):
        return None
    s = st + vst + _law_sum(law, tuple)
    for x, y in (r, dr, pos, vel, u):
        if type(x) is not float or type(y) is not float:
            return None
        s += x + y
    if s - s != 0.0:
        return None
    return [VERSION, 1, sid, seq, st, idx, r, dr, pos, vel, u, vst, law]


def dec_follower_state(o: Wire) -> FollowerState | None:
    _, _, sid, seq, st, idx, r, dr, pos, vel, u, vst, law = o
    if not (head_ok(sid, seq, st) and type(idx) is int and idx >= 0 and type(vst) is float):
        return None
    r0, r1 = r
    dr0, dr1 = dr
    pos0, pos1 = pos
    vel0, vel1 = vel
    u0, u1 = u
    if not (type(r0) is float and type(r1) is float and type(dr0) is float
            and type(dr1) is float and type(pos0) is float and type(pos1) is float
            and type(vel0) is float and type(vel1) is float and type(u0) is float
            and type(u1) is float):
        return None
    s = st + vst + r0 + r1 + dr0 + dr1 + pos0 + pos1 + vel0 + vel1 + u0 + u1
    fields = _law_in(law)
    if s - s != 0.0 or fields is None:
        return None
    m = NEW(FollowerState)
    SET(m, "__dict__", {
        "header": header(sid, seq, st), "index": idx, "r_m": (r0, r1), "dr_m_s": (dr0, dr1),
        "pos_m": (pos0, pos1), "vel_m_s": (vel0, vel1), "u_m_s": (u0, u1),
        "vehicle_stamp_s": vst, "law": fields})
    return m


def enc_target_observation(m: TargetObservation) -> Wire | None:
    h = m.header
    sid, seq, st, obs, tgt = h.sender_id, h.seq, h.stamp_s, m.observer_index, m.target_index
    pos, ost, noise = m.pos_m, m.observed_stamp_s, m.noise_std_m
    if not (head_ok(sid, seq, st) and type(obs) is int and obs >= 0 and type(tgt) is int
            and tgt >= 0 and type(ost) is float):
        return None
    s = _vec2s_sum((pos,), tuple) + st + ost
    if noise is not None:
        s += noise if type(noise) is float else _NAN
    if s - s != 0.0:
        return None
    return [VERSION, 2, sid, seq, st, obs, tgt, pos, ost, noise]


def dec_target_observation(o: Wire) -> TargetObservation | None:
    _, _, sid, seq, st, obs, tgt, pos, ost, noise = o
    if not (head_ok(sid, seq, st) and type(obs) is int and obs >= 0 and type(tgt) is int
            and tgt >= 0 and type(ost) is float):
        return None
    x, y = pos
    if type(x) is not float or type(y) is not float:
        return None
    s = st + ost + x + y
    if noise is not None:
        s += noise if type(noise) is float else _NAN
    if s - s != 0.0:
        return None
    m = NEW(TargetObservation)
    SET(m, "__dict__", {"header": header(sid, seq, st), "observer_index": obs,
                         "target_index": tgt, "pos_m": (x, y), "observed_stamp_s": ost,
                         "noise_std_m": noise})
    return m


def _truth_ok(o: Wire, seq_type: Any) -> bool:
    _, _, sid, seq, st, t, fp, fv, tp, tv = o
    if not (head_ok(sid, seq, st) and type(t) is float):
        return False
    s = st + t + _vec3s_sum(fp, seq_type) + _vec3s_sum(fv, seq_type) \
        + _vec2s_sum(tp, seq_type) + _vec2s_sum(tv, seq_type)
    return s - s == 0.0


def enc_truth_snapshot(m: TruthSnapshot) -> Wire | None:
    h = m.header
    o = [VERSION, 3, h.sender_id, h.seq, h.stamp_s, m.sim_time_s, m.follower_pos_m,
         m.follower_vel_m_s, m.target_pos_m, m.target_vel_m_s]
    return o if _truth_ok(o, tuple) else None


def dec_truth_snapshot(o: Wire) -> TruthSnapshot | None:
    if not _truth_ok(o, list):
        return None
    _, _, sid, seq, st, t, fp, fv, tp, tv = o
    m = NEW(TruthSnapshot)
    SET(m, "__dict__", {
        "header": header(sid, seq, st), "sim_time_s": t,
        "follower_pos_m": tuple(map(tuple, fp)), "follower_vel_m_s": tuple(map(tuple, fv)),
        "target_pos_m": tuple(map(tuple, tp)), "target_vel_m_s": tuple(map(tuple, tv))})
    return m


# Each twin pair and the schema it implements: tag, then `name:kind` per field in order
# (`@n`: since codec version n), as in codec.SCHEMAS.
TWINS: dict[type, tuple[int, str, Encoder, Decoder]] = {
    FollowerState: (1, "index:int r_m:vec2 dr_m_s:vec2 pos_m:vec2 vel_m_s:vec2 u_m_s:vec2 "
                    "vehicle_stamp_s:float law:law@4",
                    enc_follower_state, dec_follower_state),
    TargetObservation: (2, "observer_index:int target_index:int pos_m:vec2 "
                        "observed_stamp_s:float noise_std_m:opt_float",
                        enc_target_observation, dec_target_observation),
    TruthSnapshot: (3, "sim_time_s:float follower_pos_m:vec3s follower_vel_m_s:vec3s "
                    "target_pos_m:vec2s target_vel_m_s:vec2s",
                    enc_truth_snapshot, dec_truth_snapshot),
}
