"""Ctrl-C and SIGTERM stop a command the same way, whatever signal dispositions it inherited."""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType


@contextmanager
def interrupts() -> Iterator[None]:
    """For the block, SIGINT and SIGTERM raise KeyboardInterrupt in the main thread.

    SIGINT explicitly too: a command started with SIGINT ignored (a background job of a
    non-interactive shell, a test runner's worker) inherits that, and Python then installs
    no KeyboardInterrupt of its own, so Ctrl-C would leave the run going."""
    previous = {s: signal.signal(s, _interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt
