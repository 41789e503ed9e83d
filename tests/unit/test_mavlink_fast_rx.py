"""The one-pass receive path (agents.mavlink.fast_rx) and the one-pass setpoint framer
(agents.mavlink.wire.Framer) pinned to the layered paths they stand in for.

Two adapters, one as it runs and one that takes every datagram through the gate's screen
and `decode_datagram` alone, poll the same datagrams: good, forged, replayed, stale,
future, unsigned, MAVLink 1, mutated, truncated and spliced frames of every type a
vehicle streams, from our vehicle and from others, under a tight budget too.  Their
counters, signature streams, state and everything else they keep must stay equal.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2

from agents.mavlink import lean_common
from agents.mavlink.adapter import SETPOINT, AdapterConfig, MavlinkAdapter
from agents.mavlink.rx_gate import RxBudget
from agents.mavlink.signing import TICKS_PER_S, SignatureVerifier, signing_timestamp
from agents.mavlink.wire import Framer, encode_fields, new_codec, sign_outgoing
from tests.mavlink_fuzz import damaged, signed_frame

pytestmark = pytest.mark.timeout(180)
KEY = bytes(range(1, 33))
OTHER_KEY = bytes(range(2, 34))
NOW_S = 1_800_000_000.0
NOW = signing_timestamp(NOW_S)
ADDR = ("127.0.0.1", 14580)
# What a vehicle streams (the lean dialect's types), and one type the lean dialect lacks.
CLASSES = tuple(mavlink2.mavlink_map[i] for i in (0, 1, 24, 30, 32, 32, 32, 33, 74, 77, 111,
                                                   245, 242, 253, 147))
SETTINGS = settings(max_examples=250, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


def position_payload(draw: st.DrawFn) -> bytes:
    value = st.floats(width=32) | st.sampled_from((0.0, 1.5, -2.25, math.nan, math.inf))
    payload = lean_common.MAVLink_local_position_ned_message.unpacker.pack(
        draw(st.integers(0, 2**32 - 1)), *(draw(value) for _ in range(6)))
    return payload.rstrip(b"\0") or payload[:1] if draw(st.booleans()) else payload


@st.composite
def frames(draw: st.DrawFn) -> bytes:
    cls = draw(st.sampled_from(CLASSES))
    size = cls.unpacker.size
    if cls.id == 32 and draw(st.booleans()):
        payload = position_payload(draw)
    else:
        length = draw(st.sampled_from((size, size, max(1, size - 3), size + 2)))
        payload = draw(st.binary(min_size=length, max_size=length))
    sysid, compid = draw(st.sampled_from(((1, 1), (1, 1), (1, 1), (2, 1), (1, 190), (255, 0))))
    kind = draw(st.sampled_from(("good",) * 6 + ("unsigned", "v1", "wrong_key", "flags")))
    stamp = NOW + draw(st.sampled_from((1, 2, 3, 50, 0, -1, -61 * TICKS_PER_S,
                                        6 * TICKS_PER_S, 4 * TICKS_PER_S)))
    link = draw(st.sampled_from((0, 0, 1)))
    if kind == "v1":
        data = mavlink2.MAVLink(None, sysid, compid)
        return bytes(data.heartbeat_encode(2, 12, 129, 0x60000, 4).pack(data, force_mavlink1=True))
    frame = signed_frame(cls, payload, sysid, compid, None if kind == "unsigned" else stamp,
                  OTHER_KEY if kind == "wrong_key" else KEY, link, 2 if kind == "flags" else 0)
    if draw(st.integers(0, 7)) == 0:  # a flipped byte: CRC, header or signature
        at = draw(st.integers(0, len(frame) - 1))
        frame = frame[:at] + bytes((frame[at] ^ draw(st.integers(1, 255)),)) + frame[at + 1:]
    return frame


@st.composite
def datagrams(draw: st.DrawFn) -> bytes:
    data = damaged(draw, b"".join(draw(st.lists(frames(), min_size=1, max_size=4))))
    return data


class FakeSocket:
    """A socket whose receive queue the test fills; what is sent is counted."""

    def __init__(self) -> None:
        self.queue: list[bytes] = []
        self.sent = 0

    def recvmsg(self, _size: int, _anc: int) -> tuple[bytes, list, int, tuple[str, int]]:
        if not self.queue:
            raise BlockingIOError
        return self.queue.pop(0), [], 0, ADDR

    def sendto(self, _data: bytes, _addr: tuple[str, int]) -> None:
        self.sent += 1

    def close(self) -> None:
        pass


class Layered(MavlinkAdapter):
    """The receive path without FastRx: the gate's screen, then decode_datagram."""

    def _take(self, data: bytes, addr: tuple[str, int], received: float) -> None:
        admitted = self.gate.admit(data, addr, received)
        if admitted:
            self._datagram(admitted, addr, received)


def adapter(cls: type[MavlinkAdapter], key: bytes | None, budget: RxBudget | None,
            ) -> MavlinkAdapter:
    ad = cls(AdapterConfig(local_port=0, target_sysid=1, signing_key=key),
             clock=lambda: 50.0)
    ad.sock = FakeSocket()  # type: ignore[assignment]
    if ad.verifier is not None:
        ad.verifier.clock = lambda: NOW_S
    if budget is not None:
        ad.gate.budget = budget
    return ad


def snapshot(ad: MavlinkAdapter) -> dict[str, Any]:
    v = ad.verifier
    state = ad.state
    assert isinstance(ad.sock, FakeSocket)
    return {
        "counters": +ad.counters, "state": repr(state), "heard": ad.heard_s,
        "acks": ad.acks, "flavour": ad.flavour, "remote": ad.remote,
        "texts": ad.statustexts, "home": ad.home_amsl_m, "sent": ad.sock.sent,
        "queue": len(ad.sock.queue), "clock": ad.clock_counters(),
        "gate": (ad.gate.datagrams, ad.gate.parsed_bytes, ad.gate.carried),
        "verifier": None if v is None else (+v.counters, list(v.streams.items()), v.latest,
                                            v.evicted_floor),
    }


@SETTINGS
@given(st.lists(st.lists(datagrams(), max_size=4), min_size=1, max_size=4),
       st.sampled_from((KEY, KEY, None)),
       st.sampled_from((None, None, RxBudget(2, 200), RxBudget(8, 90))))
def test_fast_path_keeps_every_verdict_counter_and_state(
        ticks: list[list[bytes]], key: bytes | None, budget: RxBudget | None) -> None:
    fast, layered = adapter(MavlinkAdapter, key, budget), adapter(Layered, key, budget)
    for datagrams_of_tick in ticks:
        for ad in (fast, layered):
            assert isinstance(ad.sock, FakeSocket)
            ad.sock.queue.extend(datagrams_of_tick)
            ad.poll()
        assert snapshot(fast) == snapshot(layered)


def test_a_good_datagram_is_read_past_the_screen_and_forgeries_still_refused() -> None:
    ad = adapter(MavlinkAdapter, KEY, None)
    assert ad.verifier is not None
    screened: list[bytes] = []
    screen = ad.verifier.screen
    ad.verifier.screen = lambda data: screened.append(data) or screen(data)  # type: ignore
    position = lean_common.MAVLink_local_position_ned_message
    payload = position.unpacker.pack(1000, 1.0, 2.0, -3.0, 0.5, 0.25, -1.0)
    good = signed_frame(position, payload, 1, 1, NOW + 1, KEY)
    forged = signed_frame(position, payload, 1, 1, NOW + 2, OTHER_KEY)
    assert isinstance(ad.sock, FakeSocket)
    ad.sock.queue += [good, forged, good]  # the second `good` is a replay
    ad.poll()
    assert screened == []  # all three judged in one pass
    assert ad.state.pos_enu_m == (2.0, 1.0, 3.0) and ad.state.vel_enu_m_s == (0.25, 0.5, 1.0)
    assert ad.counters["signing_rejected_bad_signature"] == 1
    assert ad.counters["signing_rejected_replay"] == 1
    assert ad.verifier.counters == Counter({"accepted_signed": 1, "rejected_bad_signature": 1,
                                            "rejected_replay": 1})


# What a struct format character takes.
FIELD = {"f": st.floats(width=32), "d": st.floats(),
         "B": st.integers(0, 255) | st.just(0), "b": st.integers(-128, 127),
         "H": st.integers(0, 0xFFFF) | st.just(0), "h": st.integers(-2**15, 2**15 - 1),
         "I": st.integers(0, 2**32 - 1) | st.just(0), "i": st.integers(-2**31, 2**31 - 1),
         "Q": st.integers(0, 2**64 - 1),
         "q": st.integers(-2**63, 2**63 - 1) | st.integers(0, 2**40)}
FRAMED = (SETPOINT, lean_common.MAVLink_heartbeat_message, lean_common.MAVLink_timesync_message)


@st.composite
def messages(draw: st.DrawFn) -> tuple[Any, tuple[Any, ...]]:
    cls = draw(st.sampled_from(FRAMED))
    return cls, tuple(draw(FIELD[c]) for c in cls.unpacker.format.lstrip("<"))


@SETTINGS
@given(st.lists(messages(), min_size=1, max_size=3), st.integers(0, 255), st.booleans())
def test_framer_packs_the_bytes_encode_fields_packs(
        sent: list[tuple[Any, tuple[Any, ...]]], seq: int, signed: bool) -> None:
    """Any fields, MAVLink 2's cut of trailing zeros, the sequence wrapping, the signature."""
    ours, theirs = new_codec(245, 191, lean_common), new_codec(245, 191, lean_common)
    for mav in (ours, theirs):
        mav.seq = seq
        if signed:  # stamped ahead of the wall clock: both take the stream's timestamp
            sign_outgoing(mav, KEY, 3, signing_timestamp(NOW_S + 1e6))
    framers = {cls: Framer(ours, cls) for cls in FRAMED}
    for cls, fields in sent:
        assert bytes(framers[cls].frame(*fields)) == encode_fields(theirs, cls, *fields)
    assert ours.seq == theirs.seq and ours.signing.timestamp == theirs.signing.timestamp


@SETTINGS
@given(st.lists(st.tuples(st.integers(0, 2), st.integers(1, 3), st.integers(0, 1),
                          st.integers(-70 * TICKS_PER_S, 7 * TICKS_PER_S), st.booleans()),
                min_size=1, max_size=30),
       st.integers(1, 3))
def test_accept_and_refuse_give_check_s_verdicts_and_streams(
        frames_sent: list[tuple[int, int, int, int, bool]], max_streams: int) -> None:
    """The verifier's halves FastRx calls, against `check` of the same frames: verdicts,
    counters, the stream table in its order, evictions (a table of 1 to 3 streams)."""
    cls = lean_common.MAVLink_attitude_message
    ours, theirs = (SignatureVerifier(KEY, clock=lambda: NOW_S, allowed_unsigned=frozenset(),
                                      max_streams=max_streams) for _ in range(2))
    for link, sysid, compid, offset, good in frames_sent:
        data = signed_frame(cls, bytes(cls.unpacker.size), sysid, compid, NOW + offset,
                     KEY if good else OTHER_KEY, link)
        if good:
            verdict = ours.accept(link, sysid, compid, NOW + offset)
        else:
            verdict = ours.refuse_signature(data[:-6], data[-6:], link)
        assert verdict == theirs.check(data, cls.id, sysid, compid)
        assert (list(ours.streams.items()), ours.latest, ours.evicted_floor, ours.counters) \
            == (list(theirs.streams.items()), theirs.latest, theirs.evicted_floor,
                theirs.counters)
