"""Unit tests that run beside the real swarms must not depend on real time.

deploy/test.sh runs most unit tests at idle priority beside the swarm tests, where a test
may be off the CPU for a second between two lines (a stall guard's 0.2-s bound was seen
starved past that way).  Tests that start threads or processes, open sockets or sleep are
marked `realtime` and run beside the timed tests instead, where about a core is idle.
With ENCLOSE_TEST_NO_REALTIME=1 (that pass) an unmarked unit test that does one of those
fails at once, naming what it did, so a wrong split shows on the first run and not as a
rare starved failure.
"""

from __future__ import annotations

import os
import socket
import subprocess
import threading
import time
from collections.abc import Callable
from typing import Any

import pytest

ENV = "ENCLOSE_TEST_NO_REALTIME"


class RealTimeInUnitTest(AssertionError):
    """A unit test not marked `realtime` used real time beside the swarms."""


def _refuse(what: str) -> Callable[..., Any]:
    def refused(*_args: Any, **_kwargs: Any) -> Any:
        raise RealTimeInUnitTest(
            f"this unit test {what}: mark it `realtime` (pytest.mark.realtime) so that "
            "deploy/test.sh runs it beside the timed tests, not starved beside the swarms "
            "(tests/realtime_guard.py)")
    return refused


def active() -> bool:
    """Whether this pass refuses real time to unmarked unit tests."""
    return os.environ.get(ENV, "0") == "1"


@pytest.fixture(autouse=True)
def _no_real_time(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """In the pass beside the swarms, an unmarked unit test may not start threads or
    processes, open sockets or sleep (monkeypatch undoes it after the test)."""
    item = request.node
    if (active() and item.get_closest_marker("integration") is None
            and item.get_closest_marker("realtime") is None):
        refuse_real_time(monkeypatch)


def refuse_real_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """Threads, processes, sockets and sleep raise RealTimeInUnitTest until undone."""
    monkeypatch.setattr(threading.Thread, "start", _refuse("starts a thread"))
    monkeypatch.setattr(subprocess.Popen, "__init__", _refuse("starts a process"))
    monkeypatch.setattr(socket.socket, "__init__", _refuse("opens a socket"))
    monkeypatch.setattr(time, "sleep", _refuse("sleeps"))
