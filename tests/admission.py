"""A real swarm starts only when the machine has room for it.

The swarm tests run real time: a run whose processes wait for the CPU falls behind its
ticks and out of the paper's bounds.  How many fit side by side depends on the machine: on
one 2-core machine a paper swarm took ~0.45 of a core, on another (slower, or shared with
a busy neighbour) ~0.9, and the same four side by side that fit the first failed seven
tests on the second.  So deploy/test.sh's workers do not start a swarm on a fixed count:
each waits, before the test (outside its timeout), until the CPU that the machine's
normal-priority processes are using has fallen below the test's threshold, or for at most
a bounded time.  The idle-priority unit tests beside the timed ones (SCHED_IDLE, or nice
19 where that is missing) are not counted: they take only what is left.

Admissions go one at a time, across every worker of every pytest on the machine (an
exclusive lock on one file), at least `spacing_s` apart, so that the last swarm started
shows its load before the next one is judged.
"""

from __future__ import annotations

import fcntl
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from deploy.report.cpu_load import PROC, TICKS_PER_S, stat_fields

SCHED_IDLE = 5
BACKGROUND_NICE = 10  # at or above: background work, not counted
LOCK_FILE = Path(tempfile.gettempdir()) / "enclose-test-admission.lock"


def foreground_ticks(proc: Path = PROC) -> dict[int, int]:
    """CPU clock ticks so far (user + system, all threads) of every process that runs at
    normal priority: neither SCHED_IDLE nor niced to BACKGROUND_NICE or more."""
    ticks: dict[int, int] = {}
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            text = (entry / "stat").read_text()
        except OSError:  # ended meanwhile
            continue
        fields = stat_fields(text)
        try:
            cpu, nice, policy = int(fields[11]) + int(fields[12]), int(fields[16]), int(fields[38])
        except (IndexError, ValueError):
            continue
        if policy != SCHED_IDLE and nice < BACKGROUND_NICE:
            ticks[int(entry.name)] = cpu
    return ticks


def demand_cores(before: dict[int, int], after: dict[int, int], seconds: float) -> float:
    """Cores of CPU used between two `foreground_ticks` readings `seconds` apart.  A
    process that started in between counts whole (its ticks so far are of that time); one
    that ended does not count (its last ticks are lost with it)."""
    used = sum(t - before.get(pid, 0) for pid, t in after.items())
    return max(0.0, used / TICKS_PER_S / seconds)


@dataclass(frozen=True)
class Gate:
    """Wait for room: `threshold_cores` of foreground demand at most, measured over
    `window_s`, at least `spacing_s` after the previous admission, `wait_max_s` at most."""

    threshold_cores: float
    window_s: float = 1.0
    spacing_s: float = 6.0
    wait_max_s: float = 150.0
    lock_file: Path = LOCK_FILE

    def admit(self, measure: Callable[[float], float] | None = None,
              now: Callable[[], float] = time.monotonic,
              sleep: Callable[[float], None] = time.sleep,
              wall: Callable[[], float] = time.time) -> tuple[float, float | None]:
        """Block until admitted; (seconds waited, last demand measured, None if none)."""
        if measure is None:
            if not PROC.is_dir():  # not Linux: nothing to measure, no wait
                return 0.0, None
            measure = _measure
        start = now()
        deadline = start + self.wait_max_s
        with open(self.lock_file, "a+") as lock:
            while not _try_lock(lock):  # another worker is being admitted
                if now() >= deadline:
                    return now() - start, None
                sleep(0.2)
            try:
                sleep(max(0.0, _last_admission(lock) + self.spacing_s - wall()))
                demand = measure(self.window_s)
                while demand >= self.threshold_cores and now() < deadline:
                    demand = measure(self.window_s)
                _note_admission(lock, wall())
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)
        return now() - start, demand


def _measure(window_s: float) -> float:
    before = foreground_ticks()
    time.sleep(window_s)
    return demand_cores(before, foreground_ticks(), window_s)


def _try_lock(lock: IO[str]) -> bool:
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def _last_admission(lock: IO[str]) -> float:
    """Wall-clock time of the machine's last admission (the lock file holds it: the
    workers are separate processes); 0 if none or unreadable."""
    lock.seek(0)
    try:
        return float(lock.read().strip() or 0.0)
    except ValueError:
        return 0.0


def _note_admission(lock: IO[str], wall_s: float) -> None:
    lock.seek(0)
    lock.truncate()
    lock.write(f"{wall_s:.3f}")
    lock.flush()
