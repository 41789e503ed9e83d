"""How one sweep cell is run on this machine: `enclose run` as a child process."""

from __future__ import annotations

import contextlib
import json
import logging
import os
import secrets
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Protocol

from deploy.launch.port_slots import Slot, port_slot
from deploy.procs.pids import kill_run

log = logging.getLogger("enclose.sweep")
TIMEOUT_EXIT = 124  # as coreutils `timeout`: the cell did not finish in its time
STOP_GRACE_S = 200.0  # the launcher may wait 120 s for its recorder to write the outputs
CELL_LOG = "sweep_cell.log"
HOST_FILE = "sweep_host.json"  # where the cell ran: host, load, its swarm and ports
POLL_S = 0.5


class CellRunner(Protocol):
    def run_cell(self, argv: Sequence[str], out_dir: Path, timeout_s: float) -> int:
        """Run `enclose <argv>` writing into `out_dir`; its exit code.

        On KeyboardInterrupt, stop the run cleanly first, then re-raise."""
        ...


# Flags every cell's `enclose run` gets that are not part of the cell (its argv, compared on
# resume, stays without them): the one place to add e.g. "--no-live" for unattended cells.
RUN_EXTRA_FLAGS: tuple[str, ...] = ("--no-live",)  # nobody watches a sweep cell live


def placement_flags(slot: Slot) -> list[str]:
    """Where a cell runs: its own swarm name on the bus and its own ports, so that cells
    started side by side (`--jobs`, cluster workers) never clash."""
    swarm = f"sweep-{secrets.token_hex(4)}-s{slot.index}"
    return ["--swarm", swarm, "--port-range", slot.flag, *RUN_EXTRA_FLAGS]


class SubprocessRunner:
    """`python -m deploy.cli <argv>` in its own session, so that a terminal's Ctrl-C reaches
    only the sweep, which forwards exactly one SIGINT (a second one would cut the launcher's
    orderly stop short).

    `tick` is called while a cell runs and may raise KeyboardInterrupt to stop it cleanly
    (a parallel sweep's worker threads never see a terminal's Ctrl-C); `kill_now`, polled
    while it stops, True cuts that stop short."""

    def __init__(
        self,
        command: Sequence[str] = (sys.executable, "-m", "deploy.cli"),
        tick: Callable[[], None] | None = None,
        grace_s: float = STOP_GRACE_S,
        kill_now: Callable[[], bool] | None = None,
    ) -> None:
        self.command, self.tick, self.grace_s = list(command), tick, grace_s
        self.kill_now = kill_now

    def run_cell(self, argv: Sequence[str], out_dir: Path, timeout_s: float) -> int:
        out_dir.mkdir(parents=True, exist_ok=True)
        with port_slot(self.tick) as slot:
            flags = placement_flags(slot)
            load = LoadMeter()
            try:
                return self._run(argv, flags, out_dir, timeout_s, load)
            finally:
                load.write(out_dir / HOST_FILE, flags)

    def _run(
        self, argv: Sequence[str], flags: list[str], out_dir: Path, timeout_s: float,
        load: LoadMeter,
    ) -> int:
        with open(out_dir / CELL_LOG, "wb") as out:
            proc = subprocess.Popen(
                [*self.command, *argv, *flags],
                stdout=out,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                start_new_session=True,
                env={**os.environ, "PYTHONUNBUFFERED": "1"},
            )
        try:
            return self._wait(proc, out_dir, timeout_s, load)
        except KeyboardInterrupt:
            log.warning("interrupted: stopping %s cleanly (Ctrl-C again: kill it)", out_dir.name)
            try:
                self._stop(proc, out_dir)
            except KeyboardInterrupt:
                log.warning("second interrupt: killing the processes of %s", out_dir.name)
                kill_all(proc, out_dir)
            raise
        finally:
            if proc.poll() is None:
                kill_all(proc, out_dir)

    def _wait(
        self, proc: subprocess.Popen[bytes], out_dir: Path, timeout_s: float, load: LoadMeter
    ) -> int:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                return proc.wait(POLL_S)
            except subprocess.TimeoutExpired:
                pass
            load.sample()
            if self.tick is not None:
                self.tick()
            if time.monotonic() > deadline:
                log.error("cell %s did not finish in %.0f s: stopping it", out_dir.name, timeout_s)
                self._stop(proc, out_dir)
                return TIMEOUT_EXIT

    def _stop(self, proc: subprocess.Popen[bytes], out_dir: Path) -> None:
        if proc.poll() is not None:
            return
        proc.send_signal(signal.SIGINT)
        deadline = time.monotonic() + self.grace_s
        while time.monotonic() < deadline:
            try:
                proc.wait(POLL_S)
                return
            except subprocess.TimeoutExpired:
                if self.kill_now is not None and self.kill_now():
                    raise KeyboardInterrupt from None
        log.error("cell did not stop in %.0f s after SIGINT: killing it", self.grace_s)
        kill_all(proc, out_dir)


class LoadMeter:
    """The machine's 1-minute load average while a cell runs (parallel cells share the
    cores: the table says how loaded the machine was)."""

    def __init__(self) -> None:
        self.samples: list[float] = [os.getloadavg()[0]]

    def sample(self) -> None:
        self.samples.append(os.getloadavg()[0])

    def write(self, path: Path, flags: Sequence[str]) -> None:
        doc = {
            "host": socket.gethostname(),
            "cpus": os.cpu_count(),
            "load_1min_mean": sum(self.samples) / len(self.samples),
            "load_1min_max": max(self.samples),
            "run_flags": list(flags),
        }
        path.write_text(json.dumps(doc, indent=2) + "\n")


def kill_all(proc: subprocess.Popen[bytes], out_dir: Path) -> None:
    """SIGKILL the launcher and every process it wrote to logs/pids.json (own sessions)
    that is still the process it recorded (deploy.procs.pids: a reaped one's PID may be
    another process's by now)."""
    with contextlib.suppress(ProcessLookupError):
        proc.kill()
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(10)
    kill_run(out_dir / "logs")
