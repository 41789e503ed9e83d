"""A link's copies are recognised in a bounded window of sequence numbers."""

from __future__ import annotations

import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from transport.link_stats import SEEN_WINDOW, LinkTally


def _reference(seqs: list[int]) -> tuple[int, int]:
    """What a set of every sequence number seen, with the same window, would count."""
    seen: set[int] = set()
    top, rx, dup = -1, 0, 0
    for s in seqs:
        if s in seen or s <= top - SEEN_WINDOW:
            dup += 1
            continue
        seen.add(s)
        top, rx = max(top, s), rx + 1
    return rx, dup


@pytest.mark.parametrize("seqs", [[SEEN_WINDOW, 0], [SEEN_WINDOW, 1], [0, SEEN_WINDOW, 1, 0],
                                  [5, 5 + 2 * SEEN_WINDOW, 5 + SEEN_WINDOW]])
def test_window_edges(seqs: list[int]) -> None:
    _check(seqs)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, 3 * SEEN_WINDOW), max_size=300)
       | st.lists(st.integers(0, 40), max_size=300))
@pytest.mark.timeout(60)
def test_window_counts_like_a_set_of_everything_seen(seqs: list[int]) -> None:
    _check(seqs)


def _check(seqs: list[int]) -> None:
    tally = LinkTally("f0")
    for s in seqs:
        tally.observe(s, None)
    assert (tally.rx, tally.rx_dup) == _reference(seqs)


@pytest.mark.timeout(30)
def test_memory_stays_bounded_over_a_long_stream_and_a_forged_jump() -> None:
    tally = LinkTally("f0")
    for s in range(50_000):
        tally.observe(s, 0.01)
        if s % 7 == 0:
            tally.observe(s, 0.01)  # a copy
    tally.observe(10**12, None)  # a hostile jump must not build a 10**12-bit number
    assert sys.getsizeof(tally._window) <= SEEN_WINDOW // 8 + 64
    assert tally.rx == 50_001 and tally.rx_dup == 50_000 // 7 + 1
