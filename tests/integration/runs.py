"""Starting and cleaning up real runs in integration tests: by PID, whatever happens."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

from deploy.launch.port_slots import port_slot
from deploy.procs.pids import ProcessId, read_pids, signal_same


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def run_pids(root: Path) -> list[ProcessId]:
    """The processes of every `logs/pids.json` at or below `root` (a run, or a sweep's
    cells), with their start times (deploy.procs.pids)."""
    return [ident for logs in [root / "logs", *(p.parent for p in root.glob("*/logs/pids.json"))]
            for ident in read_pids(logs).values()]


def kill_leftovers(root: Path) -> None:
    """SIGKILL whatever of the runs under `root` still runs, by PID and start time."""
    for ident in run_pids(root):
        signal_same(ident, signal.SIGKILL)


@contextlib.contextmanager
def spawned(argv: Sequence[str], root: Path) -> Iterator[subprocess.Popen[str]]:
    """`argv` as a subprocess; afterwards it and every process its runs wrote under `root`
    are gone, even if the test failed half-way."""
    proc = subprocess.Popen(list(argv), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        kill_leftovers(root)


@contextlib.contextmanager
def spawned_run(argv: Sequence[str], root: Path) -> Iterator[subprocess.Popen[str]]:
    """An `enclose run` command as `spawned`, on ports no other run on this machine takes:
    a port slot (deploy.launch.port_slots) held while it runs, given as `--port-range`.  Without
    one, runs started at the same moment (tests side by side, `pytest -n`) can find the
    same ports free."""
    with port_slot() as slot, spawned([*argv, "--port-range", slot.flag], root) as proc:
        yield proc


def wait_for(condition: Callable[[], bool], timeout_s: float, what: str,
             period_s: float = 0.1) -> None:
    """Poll `condition` every `period_s` until it holds; fail naming `what` after
    `timeout_s`.  The integration tests' one way to wait: never a fixed sleep."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(period_s)
