"""The recorder's backlog (deploy.recording.backlog): what goes in comes out, oldest first,
a batch of each key per step, and a backlog beyond its bound loses its oldest, counted."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from deploy.recording.backlog import CHUNK_BYTES, Backlog
from transport.bus import Received

floats = st.floats(allow_nan=False, allow_infinity=True)
received = st.builds(
    Received,
    key=st.text(max_size=80) | st.just("k" * 70_000),  # longer than 16 bits count
    payload=st.binary(max_size=3000),
    recv_stamp_s=floats,
    hlc_stamp_s=st.none() | floats,
    hlc_source=st.none() | st.text(max_size=40),
    arrival_s=st.none() | floats,
)


def drain_all(backlog: Backlog, per_key: int) -> list[Received]:
    out: list[Received] = []
    while len(backlog):
        out += backlog.batch(per_key)
    return out


@pytest.mark.timeout(60)
@settings(max_examples=60, deadline=None)
@given(st.lists(st.lists(received, max_size=40), max_size=6), st.integers(1, 50))
def test_what_goes_in_comes_out_oldest_first(pieces: list[list[Received]], per_key: int) -> None:
    backlog = Backlog(["k"])
    for piece in pieces:
        backlog.take_in("k", piece)
    assert drain_all(backlog, per_key) == [r for piece in pieces for r in piece]
    assert backlog.bytes == 0 and backlog.dropped == 0


def sample(key: str, k: int, size: int = 300) -> Received:
    return Received(key, bytes([k % 256]) * size, float(k), None, None, None)


@pytest.mark.timeout(30)
def test_each_key_gets_its_batch_in_a_step() -> None:
    backlog = Backlog(["states", "status"])
    backlog.take_in("states", [sample("s", k) for k in range(1000)])
    backlog.take_in("status", [sample("t", k) for k in range(3)])
    first = backlog.batch(256)
    assert [r.key for r in first] == ["s"] * 256 + ["t"] * 3  # statuses not behind states
    assert len(backlog) == 1000 - 256


@pytest.mark.timeout(30)
def test_a_backlog_beyond_its_bound_loses_its_oldest_and_counts_them() -> None:
    backlog = Backlog(["k"], max_bytes=4 * CHUNK_BYTES)
    items = [sample("k", k) for k in range(5000)]  # ~1.6 MB packed
    backlog.take_in("k", items)
    assert backlog.bytes <= 4 * CHUNK_BYTES and backlog.peak_bytes <= 4 * CHUNK_BYTES
    kept = drain_all(backlog, 256)
    assert backlog.dropped == 5000 - len(kept) > 0
    assert kept == items[-len(kept):]  # the newest, in order


@pytest.mark.timeout(30)
def test_a_worked_off_backlog_holds_no_chunks() -> None:
    backlog = Backlog(["k"])
    for _ in range(3):
        backlog.take_in("k", [sample("k", k) for k in range(700)])
        assert backlog.bytes >= CHUNK_BYTES
        drain_all(backlog, 100)
        assert backlog.bytes == 0
    assert backlog.peak_bytes < 10 * CHUNK_BYTES


def test_a_bound_under_two_chunks_is_refused() -> None:
    with pytest.raises(ValueError, match="max_bytes"):
        Backlog(["k"], max_bytes=CHUNK_BYTES)
