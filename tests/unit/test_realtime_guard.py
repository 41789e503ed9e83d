"""tests/realtime_guard.py: beside the swarms, a unit test not marked `realtime` that uses
real time fails at once, naming what it did; undone, everything works again."""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable

import pytest

from tests.realtime_guard import RealTimeInUnitTest, refuse_real_time

pytestmark = [pytest.mark.timeout(30), pytest.mark.realtime]

USES: dict[str, Callable[[], object]] = {
    "starts a thread": lambda: threading.Thread(target=lambda: None).start(),
    "starts a process": lambda: subprocess.Popen([sys.executable, "-c", "pass"]).wait(),
    "opens a socket": lambda: socket.socket(socket.AF_INET, socket.SOCK_DGRAM).close(),
    "sleeps": lambda: time.sleep(0.0),
}


@pytest.mark.parametrize("what", sorted(USES))
def test_each_use_of_real_time_is_refused_by_name_and_works_once_undone(what: str) -> None:
    patch = pytest.MonkeyPatch()
    refuse_real_time(patch)
    try:
        with pytest.raises(RealTimeInUnitTest, match=f"{what}: mark it `realtime`"):
            USES[what]()
    finally:
        patch.undo()
    USES[what]()
