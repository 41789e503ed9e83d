"""Port ranges for runs started side by side on one machine (parallel sweep cells).

A run takes the first free ports it finds, but two launchers starting at the same moment
can both find the same block free.  A parallel cell instead holds a *slot*: an exclusive
lock (flock) on a file in the temp folder, and the port range that goes with it.  Locks
work across processes, so two sweeps, or several Dask workers on one machine, share the
slots; the kernel drops a lock when its holder exits, even when killed, so none is left
behind.
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import os
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from errors import DeployError

log = logging.getLogger("enclose.sweep")
# 15000-19999: above PX4 SITL's blocks (14540+, 14580+) and below the blocks a run searches
# when no range is given (20000+), outside the kernel's ephemeral ports (32768+).
FIRST_PORT = 15000
PORTS_PER_SLOT = 250  # 2 x 124 vehicles + the Zenoh rendezvous
SLOTS = 20
POLL_S = 0.5
# The ports of a slot a process holds anyway, named ("UDP 15000"): deploy.launch.ports.ports_held.
Held = Callable[[range], list[str]]


@dataclass(frozen=True)
class Slot:
    index: int
    ports: range

    @property
    def flag(self) -> str:
        """The value of `enclose run --port-range`."""
        return _flag(self.ports)


def slot_ports(index: int) -> range:
    start = FIRST_PORT + index * PORTS_PER_SLOT
    return range(start, start + PORTS_PER_SLOT)


def lock_dir() -> Path:
    return Path(tempfile.gettempdir()) / "enclose-port-slots"


def _try_lock(index: int, folder: Path) -> int | None:
    fd = os.open(folder / f"slot-{index}.lock", os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        return None
    return fd


def _take(folder: Path, slots: int, held: Held | None) -> tuple[int, int] | dict[int, list[str]]:
    """The first slot free and usable, as (its lock's fd, its index); else the ports in use
    of each slot passed over for them (a slot another holder has locked is not there)."""
    busy: dict[int, list[str]] = {}
    for index in range(slots):
        fd = _try_lock(index, folder)
        if fd is None:
            continue
        in_use = held(slot_ports(index)) if held is not None else []
        if not in_use:
            return fd, index
        os.close(fd)
        log.info("port slot %d passed over: %s in use", index, ", ".join(in_use[:4]))
        busy[index] = in_use
    return busy


@contextlib.contextmanager
def port_slot(
    wait: Callable[[], None] | None = None, folder: Path | None = None, slots: int = SLOTS,
    held: Held | None = None,
) -> Iterator[Slot]:
    """Hold the first free slot until the block ends; when all are held, poll, calling
    `wait` between tries (it may raise KeyboardInterrupt to give up).

    With `held` (deploy.launch.ports.ports_held, or a narrower probe), a slot whose lock is free
    but some of whose ports a process holds anyway (a test's own socket left open, another
    program) is passed over for the next; when every slot is, DeployError naming them."""
    folder = folder or lock_dir()
    folder.mkdir(parents=True, exist_ok=True)
    told = False
    while True:
        taken = _take(folder, slots, held)
        if isinstance(taken, tuple):
            fd, index = taken
            try:
                yield Slot(index, slot_ports(index))
            finally:
                os.close(fd)  # releases the lock
            return
        if len(taken) == slots:  # none is locked: waiting frees nothing
            raise DeployError("no free port block: " + "; ".join(
                f"{_flag(slot_ports(i))} ({', '.join(ports[:3])} in use)"
                for i, ports in taken.items()))
        if not told:
            log.warning("all %d port slots of this machine are in use: waiting for one", slots)
            told = True
        if wait is not None:
            wait()
        time.sleep(POLL_S)


def _flag(ports: range) -> str:
    return f"{ports.start}-{ports.stop - 1}"
