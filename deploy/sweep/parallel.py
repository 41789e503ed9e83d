"""Several sweep cells at a time: worker threads, each running one cell to its end.

The threads only wait on child processes (or on a cluster's futures), so threads are
enough.  A terminal's Ctrl-C reaches the main thread alone: it sets `StopSignals.stop`, the
runners' `tick` then raises KeyboardInterrupt in every worker thread, and each runner stops
its launcher in order (one SIGINT, outputs written), as a sequential sweep does; a second
Ctrl-C sets `kill`, which cuts those stops short.  Cells not started yet stay pending.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field

from deploy.sweep.spec import Cell

log = logging.getLogger("enclose.sweep")
POLL_S = 0.5


@dataclass(frozen=True)
class StopSignals:
    stop: threading.Event = field(default_factory=threading.Event)
    kill: threading.Event = field(default_factory=threading.Event)

    def tick(self) -> None:
        """Called by a runner while its cell runs: stop it cleanly once a stop is asked."""
        if self.stop.is_set():
            raise KeyboardInterrupt

    def kill_now(self) -> bool:
        return self.kill.is_set()


def _guarded(job: Callable[[Cell], bool], cell: Cell, signals: StopSignals) -> bool | None:
    """True done, False not done, None not started (the sweep was stopped first)."""
    if signals.stop.is_set():
        return None
    try:
        return job(cell)
    except KeyboardInterrupt:
        signals.stop.set()  # one cell interrupted stops the sweep, as in a sequential one
        return False
    except Exception:
        log.exception("cell %s: unexpected error; the sweep goes on", cell.name)
        return False


def _wait_all(futures: Sequence[Future[bool | None]], draw: Callable[[], None]) -> None:
    while not all(f.done() for f in futures):
        wait(futures, timeout=POLL_S)
        draw()


def run_parallel(
    todo: Sequence[Cell],
    job: Callable[[Cell], bool],
    jobs: int,
    signals: StopSignals,
    draw: Callable[[], None] = lambda: None,
) -> list[str]:
    """`job` on every cell, `jobs` at a time; the names of the cells run and not done.

    Raises KeyboardInterrupt once every running cell has stopped, when interrupted."""
    pool = ThreadPoolExecutor(jobs, thread_name_prefix="sweep-cell")
    futures = [pool.submit(_guarded, job, cell, signals) for cell in todo]
    try:
        _wait_all(futures, draw)
    except KeyboardInterrupt:
        signals.stop.set()
    if signals.stop.is_set():
        running = sum(f.running() for f in futures)
        log.warning("interrupted: stopping %d running cells cleanly (Ctrl-C again: kill them)",
                    running)
        pool.shutdown(wait=False, cancel_futures=True)
        try:
            _wait_all(futures, draw)
        except KeyboardInterrupt:
            signals.kill.set()
            log.warning("second interrupt: killing the cells' processes")
            _wait_all(futures, draw)
        raise KeyboardInterrupt
    pool.shutdown(wait=True)
    return [cell.name for cell, f in zip(todo, futures, strict=True) if f.result() is False]
