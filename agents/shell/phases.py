"""Start-up phase stamps of one process, on CLOCK_MONOTONIC (issue 15: fast start).

Every process on a host reads the same CLOCK_MONOTONIC, so the stamps of the launcher
and of its children line up on one time axis (`bench/bench_start.py` reads them back).
A process marks each phase as it ends (`mark("bus_open")`) and logs them all once, as
`start-up phases {json}` (seconds, CLOCK_MONOTONIC), when it is linked.

`exec` is when the kernel started the process (/proc/self/stat, 10 ms resolution);
`main` when its imports are done and its entry point runs.
"""

from __future__ import annotations

import json
import logging
import os
import time

log = logging.getLogger(__name__)
LOG_PREFIX = "start-up phases "
_stamps: dict[str, float] = {}
_cpu_s: dict[str, float] = {}  # the process's CPU time at each stamp


def process_exec_s() -> float | None:
    """When the kernel started this process, on CLOCK_MONOTONIC; None where unknown.

    /proc/<pid>/stat field 22 counts clock ticks since boot (CLOCK_BOOTTIME), which
    differs from CLOCK_MONOTONIC only by the time the host was suspended.
    """
    try:
        with open("/proc/self/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        ticks = int(fields[19])  # field 22 of the whole line; 20 after "pid (comm) state"
        hz = os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None
    suspended_s = time.clock_gettime(time.CLOCK_BOOTTIME) - time.monotonic()
    return ticks / hz - suspended_s


def mark(phase: str) -> None:
    """Stamp the end of `phase` (the first stamp of a name wins: restarts of a phase
    later in the process's life are not its start-up)."""
    if phase not in _stamps:
        _stamps[phase] = time.monotonic()
        _cpu_s[phase] = time.process_time()


def reset() -> None:
    """Forget every stamp: a process forked from another starts its own (deploy.procs.forked)."""
    _stamps.clear()
    _cpu_s.clear()


def stamps() -> dict[str, float]:
    """All phases so far, `exec` first, in the order they were marked."""
    start = process_exec_s()
    return {**({} if start is None else {"exec": start}), **_stamps}


def log_phases(who: str) -> None:
    """One log line a bench can parse (the stamps, and the CPU time the process used
    so far); also shows the durations to a reader."""
    s = stamps()
    steps = list(s.items())
    durations = ", ".join(
        f"{name} +{(t - steps[k - 1][1]) * 1e3:.0f} ms" for k, (name, t) in enumerate(steps) if k
    )
    cpu_s = time.process_time()
    log.info("%s: %s; %.2f s of CPU", who, durations, cpu_s)
    record = {"t": {k: round(v, 6) for k, v in s.items()}, "cpu_s": round(cpu_s, 4),
              "cpu_at": {k: round(v, 4) for k, v in _cpu_s.items()}}
    log.info("%s%s", LOG_PREFIX, json.dumps(record))


def parse_phases(line: str) -> tuple[dict[str, float], float] | None:
    """The stamps and CPU seconds of a `log_phases` line, or None if `line` is not one."""
    at = line.find(LOG_PREFIX)
    if at < 0:
        return None
    try:
        raw = json.loads(line[at + len(LOG_PREFIX):])
        t = {str(k): float(v) for k, v in raw["t"].items()}
        return t, float(raw["cpu_s"])
    except (ValueError, KeyError, TypeError, AttributeError):
        return None
