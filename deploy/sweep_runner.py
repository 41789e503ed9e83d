"""How one sweep cell is run (`enclose run` as a child process), and the sweep's progress line."""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Protocol

log = logging.getLogger("enclose.sweep")
TIMEOUT_EXIT = 124  # as coreutils `timeout`: the cell did not finish in its time
STOP_GRACE_S = 200.0  # the launcher may wait 120 s for its recorder to write the outputs
CELL_LOG = "sweep_cell.log"


class CellRunner(Protocol):
    def run_cell(self, argv: Sequence[str], out_dir: Path, timeout_s: float) -> int:
        """Run `enclose <argv>` writing into `out_dir`; its exit code.

        On KeyboardInterrupt, stop the run cleanly first, then re-raise."""
        ...


class SubprocessRunner:
    """`python -m deploy.cli <argv>` in its own session, so that a terminal's Ctrl-C reaches
    only the sweep, which forwards exactly one SIGINT (a second one would cut the launcher's
    orderly stop short)."""

    def __init__(
        self,
        command: Sequence[str] = (sys.executable, "-m", "deploy.cli"),
        tick: Callable[[], None] | None = None,
        grace_s: float = STOP_GRACE_S,
    ) -> None:
        self.command, self.tick, self.grace_s = list(command), tick, grace_s

    def run_cell(self, argv: Sequence[str], out_dir: Path, timeout_s: float) -> int:
        out_dir.mkdir(parents=True, exist_ok=True)
        with open(out_dir / CELL_LOG, "wb") as out:
            proc = subprocess.Popen(
                [*self.command, *argv],
                stdout=out,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                start_new_session=True,
                env={**os.environ, "PYTHONUNBUFFERED": "1"},
            )
        try:
            return self._wait(proc, out_dir, timeout_s)
        except KeyboardInterrupt:
            log.warning("interrupted: stopping the current cell cleanly (Ctrl-C again: kill it)")
            try:
                self._stop(proc, out_dir)
            except KeyboardInterrupt:
                log.warning("second interrupt: killing the cell's processes")
                kill_all(proc, out_dir)
            raise
        finally:
            if proc.poll() is None:
                kill_all(proc, out_dir)

    def _wait(self, proc: subprocess.Popen[bytes], out_dir: Path, timeout_s: float) -> int:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                return proc.wait(0.5)
            except subprocess.TimeoutExpired:
                pass
            if self.tick is not None:
                self.tick()
            if time.monotonic() > deadline:
                log.error("cell did not finish in %.0f s: stopping it", timeout_s)
                self._stop(proc, out_dir)
                return TIMEOUT_EXIT

    def _stop(self, proc: subprocess.Popen[bytes], out_dir: Path) -> None:
        if proc.poll() is not None:
            return
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(self.grace_s)
        except subprocess.TimeoutExpired:
            log.error("cell did not stop in %.0f s after SIGINT: killing it", self.grace_s)
            kill_all(proc, out_dir)


def kill_all(proc: subprocess.Popen[bytes], out_dir: Path) -> None:
    """SIGKILL the launcher and every process it wrote to logs/pids.json (own sessions)."""
    with contextlib.suppress(ProcessLookupError):
        proc.kill()
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(10)
    try:
        pids = json.loads((out_dir / "logs" / "pids.json").read_text()).values()
    except (OSError, ValueError, AttributeError):
        return
    for pid in pids:
        if isinstance(pid, int):
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)


def clock_text(seconds: float) -> str:
    s = round(max(0.0, seconds))
    if s >= 3600:
        return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"
    return f"{s // 60}:{s % 60:02d}"


class SweepProgress:
    """Cells done/total, elapsed, ETA from the mean time of the cells run so far.

    On a terminal: one line redrawn in place; elsewhere: one log line per cell."""

    def __init__(self, total: int, prior_cell_s: float, tty: bool | None = None) -> None:
        self.total, self.prior_cell_s = total, prior_cell_s
        self.tty = sys.stderr.isatty() if tty is None else tty
        self.start = time.monotonic()
        self.finished = 0  # cells counted done/failed/skipped
        self.ran_s: list[float] = []
        self.label = ""
        self.cell_start = self.start

    def skipped(self, count: int) -> None:
        self.finished += count

    def begin(self, position: int, label: str) -> None:
        self.label, self.cell_start = f"[{position}/{self.total}] {label}", time.monotonic()
        if self.tty:
            self.draw()
        else:
            log.info("%s  (elapsed %s, ETA %s)", self.label, *self._times())

    def end(self, wall_s: float) -> None:
        self.ran_s.append(wall_s)
        self.finished += 1

    def eta_s(self) -> float:
        mean = sum(self.ran_s) / len(self.ran_s) if self.ran_s else self.prior_cell_s
        in_cell = time.monotonic() - self.cell_start if self.label else 0.0
        remaining = self.total - self.finished
        return max(0.0, remaining * mean - min(in_cell, mean))

    def _times(self) -> tuple[str, str]:
        eta = clock_text(self.eta_s())
        return clock_text(time.monotonic() - self.start), eta if self.ran_s else f"~{eta}"

    def draw(self) -> None:
        if not self.tty:
            return
        fraction = self.finished / self.total if self.total else 1.0
        bar = "#" * int(20 * fraction)
        elapsed, eta = self._times()
        line = f"sweep [{bar:<20}] {self.finished}/{self.total} {elapsed} ETA {eta} {self.label}"
        width = max(40, shutil.get_terminal_size().columns - 1)
        sys.stderr.write("\r" + line[:width].ljust(width))
        sys.stderr.flush()

    def close(self) -> None:
        if self.tty:
            sys.stderr.write("\n")
            sys.stderr.flush()
