"""Which process a PID is: a run's `logs/pids.json`, and signals sent only to the same process.

A PID names a process only until that process is reaped; then the kernel hands it to the
next process it starts (soon, on a busy machine; as root, a sweep's SIGKILL to a stale
PID could hit anything).  So pids.json records each child's PID with its start time
(field 22 of /proc/<pid>/stat: clock ticks after boot, fixed for the life of a process):

    {"sim": {"pid": 4242, "start_ticks": 1234567}, "follower-0": {...}, ...}

and `signal_same` signals a PID only if the process living there started at that time.
It opens a pidfd first (Linux >= 5.3): the pidfd pins the process it was opened on, so
once the start time matches, the signal cannot reach a successor however late it is
sent.  The launcher's own kills go through its unreaped children's handles
(deploy.procs.supervisor): a child that is not reaped keeps its PID.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

log = logging.getLogger(__name__)
PIDS_FILE = "pids.json"
StatReader = Callable[[int], str | None]  # a PID's /proc/<pid>/stat line, None if gone


@dataclass(frozen=True)
class ProcessId:
    """A process, not just a PID: `start_ticks` tells it from a later one with that PID."""

    pid: int
    start_ticks: int | None  # None: not readable when recorded (then never signalled)

    def as_dict(self) -> dict[str, int | None]:
        return {"pid": self.pid, "start_ticks": self.start_ticks}


def read_stat(pid: int) -> str | None:
    try:
        return Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None


def start_ticks(pid: int, stat: StatReader = read_stat) -> int | None:
    """Field 22 of the PID's stat line (after the command name, which may hold spaces
    and parentheses: split after its last ')'), or None if there is no such process."""
    line = stat(pid)
    if line is None or ")" not in line:
        return None
    fields = line[line.rindex(")") + 2:].split()
    try:
        return int(fields[19])  # fields[0] is field 3 (state)
    except (IndexError, ValueError):
        return None


def identify(pid: int, stat: StatReader = read_stat) -> ProcessId:
    """The process at `pid` now: call it while it cannot have been reaped (our child)."""
    return ProcessId(pid, start_ticks(pid, stat))


def is_alive(ident: ProcessId, stat: StatReader = read_stat) -> bool:
    """True while the process `ident` names exists (a zombie too)."""
    return ident.start_ticks is not None and start_ticks(ident.pid, stat) == ident.start_ticks


def signal_same(ident: ProcessId, signum: int, stat: StatReader = read_stat) -> bool:
    """Send `signum` to the process `ident` names if it is still the one at its PID;
    True if sent.  A reaped process (its PID free, or another process's) is left alone."""
    if ident.start_ticks is None:
        return False
    try:
        fd: int | None = os.pidfd_open(ident.pid)
    except ProcessLookupError:
        return False
    except (OSError, AttributeError):  # no pidfd here: check, then kill (a tiny race)
        fd = None
    try:
        if start_ticks(ident.pid, stat) != ident.start_ticks:
            return False
        if fd is None:
            os.kill(ident.pid, signum)
        else:
            signal.pidfd_send_signal(fd, signum)
        return True
    except ProcessLookupError:
        return False
    except PermissionError:
        log.warning("pid %d: not ours to signal", ident.pid)
        return False
    finally:
        if fd is not None:
            os.close(fd)


def write_pids(log_dir: Path, ids: Mapping[str, ProcessId]) -> None:
    """pids.json, replaced atomically (an outside cleanup may read it at any time)."""
    tmp = log_dir / f"{PIDS_FILE}.tmp"
    tmp.write_text(json.dumps({k: v.as_dict() for k, v in ids.items()}, indent=2) + "\n")
    tmp.replace(log_dir / PIDS_FILE)


def read_pids(log_dir: Path) -> dict[str, ProcessId]:
    """A run's `logs/pids.json`; entries that are not {pid, start_ticks} are skipped."""
    try:
        raw = json.loads((log_dir / PIDS_FILE).read_text())
    except (OSError, ValueError):
        return {}
    out: dict[str, ProcessId] = {}
    for name, entry in raw.items() if isinstance(raw, dict) else ():
        with contextlib.suppress(KeyError, TypeError):
            pid, ticks = entry["pid"], entry["start_ticks"]
            if isinstance(pid, int) and pid > 0 and (ticks is None or isinstance(ticks, int)):
                out[str(name)] = ProcessId(pid, ticks)
    return out


def kill_run(log_dir: Path, stat: StatReader = read_stat) -> list[str]:
    """SIGKILL every process of a run that is still the one its pids.json names; the
    names of those signalled."""
    return [name for name, ident in read_pids(log_dir).items()
            if signal_same(ident, signal.SIGKILL, stat)]
