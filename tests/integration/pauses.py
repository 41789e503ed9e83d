"""Freeze processes of a real `enclose run` (SIGSTOP, then SIGCONT) on a plan, by PID.

Shared by tests/integration/test_pause_recovery.py and bench/bench_pauses.py.  Every
stopped process is continued whatever happens, and `spawned` kills the whole run by
PID afterwards.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from deploy.procs.pids import read_pids
from tests.integration.runs import spawned_run, wait_for


@dataclass(frozen=True)
class Pause:
    at_s: float  # experiment time (the recorder's progress) at which to stop
    process: str  # name in logs/pids.json: sim, follower-0, target-0, ...
    length_s: float


@dataclass(frozen=True)
class PausedRun:
    returncode: int
    output: str
    pauses_wall_s: list[tuple[float, float]]  # (stop, resume) per pause, time.time()


def experiment_time_s(out: Path) -> float:
    try:
        progress = json.loads((out / "progress.json").read_text())
    except (OSError, ValueError):
        return -1.0
    return float(progress.get("t_s") or -1.0) if progress.get("state") == "running" else -1.0


def freeze(pid: int, length_s: float) -> tuple[float, float]:
    """SIGSTOP `pid` for `length_s` (the disturbance itself), then SIGCONT, always."""
    stopped = time.time()
    os.kill(pid, signal.SIGSTOP)
    try:
        time.sleep(length_s)
    finally:
        os.kill(pid, signal.SIGCONT)
    return stopped, time.time()


def run_with_pauses(out: Path, duration_s: float, plan: list[Pause], *extra: str,
                    start_timeout_s: float = 120.0) -> PausedRun:
    argv = [sys.executable, "-m", "deploy.cli", "run", "--out", str(out), "--duration",
            str(duration_s), "--link-timeout", "60", "--no-figures", *extra]
    walls: list[tuple[float, float]] = []
    with spawned_run(argv, out) as proc:
        for pause in sorted(plan, key=lambda p: p.at_s):
            wait_for(lambda p=pause: experiment_time_s(out) >= p.at_s or proc.poll() is not None,
                     start_timeout_s + pause.at_s * 3.0, f"the run to reach {pause.at_s} s")
            if proc.poll() is not None:
                break
            pid = read_pids(out / "logs")[pause.process].pid
            with contextlib.suppress(ProcessLookupError):
                walls.append(freeze(pid, pause.length_s))
        output, _ = proc.communicate(timeout=start_timeout_s + duration_s * 3.0)
    return PausedRun(proc.returncode, output, walls)
