"""deploy.native_memory: freed memory goes back to the kernel, on the recorder's period."""

from __future__ import annotations

import os

import pytest

from deploy.cpu_load import process_status_kb
from deploy.native_memory import PeriodicTrim, _malloc_trim, trim_free_memory

pytestmark = pytest.mark.timeout(60)


def _rss_anon_mb() -> float:
    kb = process_status_kb(os.getpid(), "RssAnon")
    assert kb is not None
    return kb / 1024


@pytest.mark.skipif(_malloc_trim() is None, reason="no glibc malloc_trim here")
def test_memory_freed_under_a_live_block_goes_back_only_when_trimmed() -> None:
    # 4-kB blocks come from malloc (not Python's small-object arenas); the last one, kept,
    # pins the top of the heap, so glibc cannot give the freed ones back by itself.
    blocks = [bytes(4000) + bytes([i % 256]) for i in range(25_000)]  # ~100 MB
    keep = blocks[-1]
    held = _rss_anon_mb()
    del blocks
    freed_untrimmed = _rss_anon_mb()
    assert trim_free_memory() is True
    trimmed = _rss_anon_mb()
    assert keep[-1] == 24_999 % 256
    assert freed_untrimmed > held - 20  # freeing alone kept most of it resident
    assert trimmed < freed_untrimmed - 60  # the trim handed it back


def test_the_periodic_trim_waits_a_period_from_its_first_call() -> None:
    trim = PeriodicTrim(period_s=30.0)
    assert [trim.maybe(t) for t in (100.0, 110.0, 129.9, 130.0, 140.0, 160.0, 161.0)] == [
        False, False, False, True, False, True, False]
    assert trim.calls == 2
