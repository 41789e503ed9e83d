"""The cheap per-message checks and tallies pinned to the generic code they replace.

`check` (transport.message_checks) sums a message's numbers instead of testing each one,
`AgeHistogram.add` (transport.link_stats) counts bins in a dict until read, and
`ClockBook.to_local` copies field dicts instead of `dataclasses.replace`: here each is
compared with the code before issue 15, kept below as the reference, on random and
hostile values (NaN, inf, huge, ints, bools, strings, wrong lengths).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from transport.key_exprs import SwarmKeys, parse_key
from transport.link_stats import AGE_MAX_S, AgeHistogram, latency_histogram
from transport.message_checks import DEFAULT_LIMITS, Limits, _time_reason, check, key_rule
from transport.messages import (
    ClockProbe,
    FollowerState,
    Header,
    Message,
    ProcessStatus,
    RunControl,
    TargetObservation,
    TruthSnapshot,
)
from transport.peer_clock import _STAMP_FIELDS, ClockBook, ClockSample

pytestmark = pytest.mark.timeout(120)
KEYS = SwarmKeys("chk")
NOW = 1_800_000_000.0


# ---- the reference: transport.message_checks before issue 15 (with the rules added since) ----
def _finite(values: Iterable[Any]) -> bool:
    return all(isinstance(v, int | float) and math.isfinite(v) for v in values)


def _bounded(vectors: Iterable[tuple[float, ...]], bound: float) -> bool:
    return all(math.hypot(*v) <= bound for v in vectors)


def check_reference(msg: Any, key: str, now_s: float, lim: Limits = DEFAULT_LIMITS) -> str | None:
    rule = key_rule(key)
    if rule is not None and msg.header.sender_id != rule.owner:
        return "sender"
    if isinstance(msg, ProcessStatus):
        return None
    if isinstance(msg, RunControl):
        ok = _finite((msg.start_stamp_s, msg.duration_s)) and msg.duration_s >= 0
        return _time_reason(msg.header.stamp_s, now_s, lim) or (None if ok else "impossible")
    reason = _time_reason(msg.header.stamp_s, now_s, lim)
    if reason is not None:
        return reason
    if isinstance(msg, FollowerState):
        positions = [msg.r_m, msg.pos_m]
        speeds = [msg.dr_m_s, msg.vel_m_s, msg.u_m_s]
        numbers = [*(x for v in positions + speeds for x in v), msg.vehicle_stamp_s]
        if not _finite(numbers):
            return "nonfinite"
        if msg.vehicle_stamp_s > now_s + lim.future_s:
            return "future_stamp"
        if not (_bounded(positions, lim.max_pos_m) and _bounded(speeds, lim.max_speed_m_s)):
            return "impossible"
        return None
    if isinstance(msg, TargetObservation):
        if not _finite((*msg.pos_m, msg.observed_stamp_s)):
            return "nonfinite"
        reason = _time_reason(msg.observed_stamp_s, now_s, lim)
        if reason is not None:
            return reason
        if msg.observed_stamp_s > msg.header.stamp_s:
            return "future_stamp"
        return None if _bounded([msg.pos_m], lim.max_pos_m) else "impossible"
    if isinstance(msg, TruthSnapshot):
        vecs = [*msg.follower_pos_m, *msg.follower_vel_m_s, *msg.target_pos_m, *msg.target_vel_m_s]
        return None if all(_finite(v) for v in vecs) else "nonfinite"
    return None


class AgeHistogramReference:
    def __init__(self, bin_s: float, max_s: float) -> None:
        self.bin_s = bin_s
        self.bins = np.zeros(round(max_s / bin_s), dtype=np.int64)
        self.count, self.sum_s = 0, 0.0

    def add(self, age_s: float) -> None:
        k = min(max(int(age_s / self.bin_s), 0), len(self.bins) - 1) if age_s == age_s else 0
        self.bins[k] += 1
        self.count += 1
        self.sum_s += min(max(age_s, 0.0), AGE_MAX_S) if age_s == age_s else 0.0


# ---- strategies ----------------------------------------------------------------------------
num = st.one_of(
    st.floats(-2e4, 2e4), st.floats(), st.sampled_from([math.nan, math.inf, -math.inf, 1e308,
                                                        -1e308, 1e5, 1e3, 1e5 + 1e-9, 1e4,
                                                        1e4 + 1e-9]),
    st.integers(-10**6, 10**6), st.booleans())
odd = num | st.sampled_from(["x", None, (1.0,), ()])  # what a message built in code may hold
stamp = st.floats(NOW - 100.0, NOW + 2.0) | st.sampled_from([NOW, NOW + 0.5, math.nan, math.inf])
v2 = st.tuples(num, num) | st.tuples(odd, odd) | st.tuples(num) | st.tuples(num, num, num)
v3 = st.tuples(num, num, num)
sender = st.sampled_from(["follower-1", "follower-2", "sim-0", "launcher-0"])
header = st.builds(Header, sender, st.integers(0, 9), stamp)
link = st.tuples(st.integers(0, 3), num, num)
law = st.dictionaries(st.sampled_from(["a", "b", "c"]),
                      num | v2 | st.lists(link, min_size=1, max_size=3).map(tuple), max_size=3)

MESSAGES = st.one_of(
    st.builds(FollowerState, header, st.integers(0, 3), v2, v2, v2, v2, v2, stamp | num, law),
    st.builds(TargetObservation, header, st.integers(0, 3), st.integers(0, 1), v2, stamp | odd),
    st.builds(TruthSnapshot, header, num, st.lists(v3, max_size=3).map(tuple),
              st.lists(v3, max_size=3).map(tuple), st.lists(v2, max_size=2).map(tuple),
              st.lists(v2, max_size=2).map(tuple)),
    st.builds(RunControl, header, st.sampled_from(["start", "stop"]), stamp | num, num),
    st.builds(ProcessStatus, header, st.just("sim"), st.just(0), st.just("running")),
    st.builds(ClockProbe, header, num),
)
KEY = st.sampled_from([KEYS.follower_state(1), KEYS.follower_estimate(1), KEYS.sensor_targets(1),
                       KEYS.truth(), KEYS.control(), KEYS.status("sim", 0), KEYS.clock("sim", 0),
                       "other/key", "enclose/chk/follower/x/state"])


def verdict(fn: Any, msg: Message, key: str, now_s: float, lim: Limits) -> Any:
    try:
        return fn(msg, key, now_s, lim)
    except Exception as exc:  # the reference raises on some junk: so must the fast one
        return type(exc).__name__


@settings(max_examples=300, deadline=None)
@given(MESSAGES, KEY, st.sampled_from([NOW, NOW - 1.0, NOW + 100.0]),
       st.sampled_from([DEFAULT_LIMITS, Limits(max_age_s=math.inf), Limits(future_s=0.0),
                        Limits(max_speed_m_s=1.0)]))
def test_check_same_verdict_as_reference(msg: Message, key: str, now_s: float,
                                         lim: Limits) -> None:
    assert verdict(check, msg, key, now_s, lim) == verdict(check_reference, msg, key, now_s, lim)


def test_follower_bounds_at_the_edge() -> None:
    """Bounds are still `hypot <= limit`, not an approximation of it."""
    base = dict(r_m=(0.0, 0.0), dr_m_s=(0.0, 0.0), pos_m=(0.0, 0.0),
                vel_m_s=(0.0, 0.0), u_m_s=(0.0, 0.0), vehicle_stamp_s=NOW)
    key = KEYS.follower_state(1)
    for field, limit in (("r_m", 1e5), ("pos_m", 1e5), ("dr_m_s", 1e3), ("u_m_s", 1e3)):
        verdicts = []
        for value in (limit, math.nextafter(limit, math.inf)):
            for vec in ((value, 0.0), (value / math.sqrt(2), value / math.sqrt(2))):
                over: dict[str, object] = {field: vec}
                msg = FollowerState(Header("follower-1", 0, NOW), 1,
                                    **{**base, **over})  # type: ignore[arg-type]
                assert check(msg, key, NOW) == check_reference(msg, key, NOW)
                verdicts.append(check(msg, key, NOW))
        assert verdicts[0] is None and verdicts[2] == "impossible", field


def test_key_caches_are_bounded() -> None:
    info = parse_key.cache_info()
    assert info.maxsize is not None and info.maxsize <= 4096
    for k in range(3000):
        parse_key(f"enclose/x/follower/{k}/state")
    assert parse_key.cache_info().currsize <= info.maxsize


@settings(max_examples=150, deadline=None)
@given(st.lists(st.floats() | st.sampled_from([0.0, 1e-4, 9.99995, 10.0, 1e9, -1.0]),
                max_size=60), st.booleans())
def test_age_histogram_same_as_reference(ages: list[float], latency: bool) -> None:
    hist = latency_histogram() if latency else AgeHistogram()
    ref = AgeHistogramReference(hist.bin_s, len(hist.bins) * hist.bin_s)
    for k, age in enumerate(ages):
        if math.isinf(age / hist.bin_s):
            continue  # the reference crashed on these (int(inf)); see the test below
        hist.add(age)
        ref.add(age)
        if k % 7 == 0:  # reads in between: what is pending goes into the bins
            assert hist.percentile_s(50) is not None
    assert hist.count == ref.count and hist.sum_s == pytest.approx(ref.sum_s, rel=1e-12)
    assert np.array_equal(hist.bins, ref.bins)
    assert np.array_equal(hist.blocks, ref.bins.reshape(-1, AgeHistogram.BLOCK).sum(axis=1))


def test_age_histogram_infinite_age_lands_in_the_last_bin() -> None:
    hist = AgeHistogram()
    hist.add(math.inf)
    hist.add(1e308)
    assert hist.bins[-1] == 2 and hist.sum_s == 2 * AGE_MAX_S
    other = AgeHistogram()
    other.add(0.00015)
    hist.merge(other)
    assert hist.count == 3 and hist.bins[1] == 1 and hist.percentile_s(1) == pytest.approx(1.5e-4)


@settings(max_examples=100, deadline=None)
@given(MESSAGES, st.floats(-10.0, 10.0).filter(bool))
def test_to_local_same_as_replace(msg: Message, offset_s: float) -> None:
    book = ClockBook()
    book.add(msg.header.sender_id, 1.0, ClockSample(offset_s, 0.001, 5.0))
    header = dataclasses.replace(msg.header, stamp_s=msg.header.stamp_s - offset_s)
    try:
        extra = {f: getattr(msg, f) - offset_s for f in _STAMP_FIELDS.get(type(msg), ())}
    except TypeError:  # a stamp that is not a number: both raise
        with pytest.raises(TypeError):
            book.to_local(msg)
        return
    expected = msg if isinstance(msg, ClockProbe) else dataclasses.replace(
        msg, header=header, **extra)
    local = book.to_local(msg)
    assert repr(local) == repr(expected) and type(local) is type(expected)
