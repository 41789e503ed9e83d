"""The signature verifier's stream table is bounded: the least recently accepted stream is
forgotten, counted, and none of its frames can be replayed as a new stream afterwards."""

from __future__ import annotations

import hashlib
import time
import tracemalloc
from collections import Counter

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.mavlink.signing import (
    MAX_STREAMS,
    NEW_STREAM_WINDOW,
    TICKS_PER_S,
    SignatureVerifier,
    signature,
    signing_timestamp,
)

KEY = hashlib.sha256(b"vehicle 3").digest()
NOW_S = 1_800_000_000.0
NOW = signing_timestamp(NOW_S)
MSG_ID = 76  # COMMAND_LONG


def frame(link_id: int, sysid: int, compid: int, stamp: int, key: bytes = KEY) -> bytes:
    """A signed MAVLink 2 frame, built by hand (pymavlink would take seconds for 10^5);
    the verifier checks the signature, not the CRC."""
    payload = bytes(33)
    head = bytes((0xFD, len(payload), 0x01, 0, 0, sysid, compid)) + MSG_ID.to_bytes(3, "little")
    signed_part = head + payload + b"\0\0" + bytes((link_id,)) + stamp.to_bytes(6, "little")
    return signed_part + signature(key, signed_part)


def check(v: SignatureVerifier, f: bytes) -> str | None:
    return v.check(f, MSG_ID, f[5], f[6])


def triple(i: int) -> tuple[int, int, int]:
    """The i-th of 10^5 distinct (link_id, sysid, compid) triples."""
    return i % 256, 1 + (i // 256) % 255, (i // (256 * 255)) % 256


def flood(v: SignatureVerifier, start: int, n: int) -> None:
    for i in range(start, start + n):
        assert check(v, frame(*triple(i), NOW + i)) is None


def test_1e5_varied_triples_keep_the_table_at_its_bound_and_memory_flat() -> None:
    sink: Counter[str] = Counter()
    v = SignatureVerifier(KEY, clock=lambda: NOW_S + 2.0, evictions=sink)
    tracemalloc.start()
    try:
        flood(v, 0, 10_000)
        before, _ = tracemalloc.get_traced_memory()
        flood(v, 10_000, 90_000)
        after, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(v.streams) == MAX_STREAMS
    assert v.counters["streams_evicted"] == sink["signing_streams_evicted"] \
        == 100_000 - MAX_STREAMS
    # The memory the table holds after 10^4 streams is what it holds after 10^5 (unbounded,
    # each entry took ~100 bytes: 10^5 streams held 10 MB).
    assert abs(after - before) < 4096


def test_an_evicted_stream_is_not_replayed_as_a_new_one() -> None:
    v = SignatureVerifier(KEY, clock=lambda: NOW_S + 2.0, max_streams=8)
    legit = [frame(0, 3, 191, NOW - 10 * TICKS_PER_S + k) for k in range(5)]
    assert [check(v, f) for f in legit] == [None] * 5
    flood(v, 1000, 8)  # a key holder's new streams push the legitimate one out
    assert (0, 3, 191) not in v.streams and v.counters["streams_evicted"] == 1
    # 10 s old: the spec's new-stream rule alone (a minute) would take these back.
    assert NEW_STREAM_WINDOW > 10 * TICKS_PER_S
    assert [check(v, f) for f in legit] == ["replay"] * 5
    # The sender's next frame, stamped from its clock, is taken: it was never locked out.
    assert check(v, frame(0, 3, 191, signing_timestamp(NOW_S + 1.0))) is None


def test_the_most_recently_accepted_streams_are_kept() -> None:
    v = SignatureVerifier(KEY, clock=lambda: NOW_S + 2.0, max_streams=4)
    flood(v, 0, 4)
    assert check(v, frame(*triple(0), NOW + 100)) is None  # triple 0 is now the newest
    flood(v, 10, 1)
    assert triple(0) in v.streams and triple(1) not in v.streams


def test_a_bound_below_one_is_refused() -> None:
    with pytest.raises(Exception, match="max_streams"):
        SignatureVerifier(KEY, max_streams=0)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 5), st.integers(-200, 200)), max_size=120),
       st.integers(1, 4))
def test_no_stream_ever_goes_back_whatever_is_evicted(ops: list[tuple[int, int]],
                                                      bound: int) -> None:
    """Whatever the order of streams and stamps, a frame is accepted only if stamped above
    every frame ever accepted on its stream, and the table never exceeds its bound."""
    v = SignatureVerifier(KEY, clock=lambda: NOW_S, max_streams=bound)
    highest: dict[tuple[int, int, int], int] = {}
    for link, offset in ops:
        stream = (link, 3, 191)
        stamp = NOW + offset
        if check(v, frame(*stream, stamp)) is None:
            assert stamp > highest.get(stream, -1)
            highest[stream] = stamp
        assert len(v.streams) <= bound


@pytest.mark.realtime
def test_a_vehicle_counts_its_evictions_with_its_signing_counters() -> None:
    from agents.mavlink.signing_keys import vehicle_key
    from agents.scenario.model import HomeConfig, VehicleConfig
    from sim_backend.runtime import SimConfig, Simulator, grid_spawn_ned
    from tests.unit.test_mavlink_vehicle_keys import SECRET, disarm, signer

    sim = Simulator(grid_spawn_ned(1), VehicleConfig(), HomeConfig(),
                    SimConfig(listen_base_port=0, send_base_port=9, signing_secret=SECRET))
    try:
        ep, row = sim.endpoints[0], sim._rows[0]
        now = time.time()
        # 266 streams, each stamped from a clock that moves on (as a real sender's): a new
        # stream stamped at or below the newest evicted one would be refused.
        for link in range(MAX_STREAMS + 10):
            stamp_s = now + 0.001 * link
            ep.parse_datagram(disarm(signer(vehicle_key(SECRET, 1), stamp_s, link_id=link % 256,
                                            sysid=245 if link < 256 else 246)),
                              ("127.0.0.1", 9), 0.0, row)
        assert sim.counters["commands"] == MAX_STREAMS + 10
        assert sim.counters["signing_streams_evicted"] == 10
    finally:
        sim.close()
