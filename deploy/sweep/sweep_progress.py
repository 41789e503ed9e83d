"""The sweep's progress: cells done/total, elapsed time and ETA, on one line or in the log."""

from __future__ import annotations

import logging
import shutil
import sys
import threading
import time

log = logging.getLogger("enclose.sweep")


def clock_text(seconds: float) -> str:
    s = round(max(0.0, seconds))
    if s >= 3600:
        return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"
    return f"{s // 60}:{s % 60:02d}"


class SweepProgress:
    """Cells done/total, elapsed, ETA from the mean time of the cells run so far.

    On a terminal: one line redrawn in place; elsewhere: one log line per cell.  With `jobs`
    cells at a time the ETA divides the remaining cells among them; cells may begin and end
    from several threads."""

    def __init__(
        self, total: int, prior_cell_s: float, tty: bool | None = None, jobs: int = 1
    ) -> None:
        self.total, self.prior_cell_s, self.jobs = total, prior_cell_s, max(1, jobs)
        self.lock = threading.Lock()
        self.tty = sys.stderr.isatty() if tty is None else tty
        self.start = time.monotonic()
        self.finished = 0  # cells counted done/failed/skipped
        self.ran_s: list[float] = []
        self.label = ""
        self.cell_start = self.start

    def skipped(self, count: int) -> None:
        self.finished += count

    def begin(self, position: int, label: str) -> None:
        with self.lock:
            self.label = f"[{position}/{self.total}] {label}"
            self.cell_start = time.monotonic()
        if self.tty:
            self.draw()
        else:
            log.info("%s  (elapsed %s, ETA %s)", self.label, *self._times())

    def end(self, wall_s: float) -> None:
        with self.lock:
            self.ran_s.append(wall_s)
            self.finished += 1

    def eta_s(self) -> float:
        mean = sum(self.ran_s) / len(self.ran_s) if self.ran_s else self.prior_cell_s
        in_cell = time.monotonic() - self.cell_start if self.label else 0.0
        remaining = self.total - self.finished
        return max(0.0, remaining * mean / self.jobs - min(in_cell, mean))

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
        with self.lock:
            sys.stderr.write("\r" + line[:width].ljust(width))
            sys.stderr.flush()

    def close(self) -> None:
        if self.tty:
            sys.stderr.write("\n")
            sys.stderr.flush()
