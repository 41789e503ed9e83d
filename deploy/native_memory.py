"""Handing memory a long-lived process has freed back to the kernel (glibc's `malloc_trim`).

The recorder decodes every message of a run and drops it a moment later, while Zenoh's
threads allocate the samples it drains: glibc keeps what is freed in the arena of the
thread that allocated it, and gives it back to the kernel only from the top of each heap.
Over an hour of the paper's case its resident memory crept up by ~8 % though its Python
heap stayed flat (BENCHMARKS.md, "Long runs").  `malloc_trim(0)` returns every free page of
every arena (madvise), without moving anything: it costs a few milliseconds on a heap of
this size, so the recorder calls it once every `TRIM_PERIOD_S`.  Elsewhere than on glibc
(musl, macOS) there is nothing to call and `trim_free_memory` says so.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
from collections.abc import Callable

TRIM_PERIOD_S = 30.0


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        trim = ctypes.CDLL(name).malloc_trim
    except (OSError, AttributeError):  # no libc by that name, or not glibc
        return None
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return trim


def trim_free_memory() -> bool | None:
    """Give the kernel the pages glibc holds free; True if some were released, None
    where the C library has no `malloc_trim`."""
    trim = _malloc_trim()
    return None if trim is None else bool(trim(0))


class PeriodicTrim:
    """`trim_free_memory` at most once every `period_s` of the clock it is given."""

    def __init__(self, period_s: float = TRIM_PERIOD_S) -> None:
        self.period_s = period_s
        self.calls = 0
        self._next_s: float | None = None

    def maybe(self, now_s: float) -> bool:
        """Trim if the period has passed since the last trim (the first call only starts
        the clock); True if it trimmed."""
        if self._next_s is None:
            self._next_s = now_s + self.period_s
            return False
        if now_s < self._next_s:
            return False
        self._next_s = now_s + self.period_s
        self.calls += 1
        trim_free_memory()
        return True
