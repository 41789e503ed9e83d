"""`enclose.simulator.running_sim`: the MAVLink vehicle simulator (`enclose sim`) as a child
process on ports of its own, for a client's tests; stopped by its PID when the block ends.

Its ports come from a port slot (deploy.launch.port_slots), the lock parallel sweep cells take,
so that simulators and runs started side by side never share a port; a slot a port of
which some other process holds (a client's socket a failed test left open) is passed over.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from agents.mavlink.modes import FLAVOURS
from agents.mavlink.signing_keys import write_key
from deploy.launch.port_slots import port_slot
from deploy.launch.ports import ports_held
from errors import ConfigError, SimulatorError

HOST = "127.0.0.1"
READY_LINE = "listening on"  # deploy.commands.sim logs it once every vehicle's socket is bound
START_TIMEOUT_S = 30.0
STOP_TIMEOUT_S = 5.0
MAX_VEHICLES = 124  # two blocks of this fit a port slot


@dataclass(frozen=True)
class Vehicle:
    """One simulated vehicle: MAVLink system `sysid`, receiving on `listen_port` and sending
    its telemetry to `send_port`, where a client listens."""

    sysid: int
    listen_port: int
    send_port: int
    host: str = HOST

    @property
    def mavsdk_address(self) -> str:
        """For MAVSDK's `add_any_connection` / `System.connect`."""
        return f"udpin://{self.host}:{self.send_port}"

    @property
    def pymavlink_address(self) -> str:
        """For pymavlink's `mavutil.mavlink_connection`."""
        return f"udpin:{self.host}:{self.send_port}"


@dataclass(frozen=True)
class SimEndpoints:
    """A running simulator: its vehicles, flavour, signing key (None: unsigned), PID, log."""

    vehicles: tuple[Vehicle, ...]
    flavour: str
    signing_key: bytes | None
    key_file: Path | None
    pid: int
    log_path: Path

    def __getitem__(self, index: int) -> Vehicle:
        return self.vehicles[index]

    def output(self) -> str:
        """What the simulator wrote so far (its closing message counts once stopped)."""
        return self.log_path.read_text(errors="replace")


@contextlib.contextmanager
def running_sim(vehicles: int = 1, flavour: str = "px4", signing: bool = False,
                workdir: Path | None = None) -> Iterator[SimEndpoints]:
    """`vehicles` on a 5 m grid, `flavour` "px4" or "ardupilot"; `signing`: a fresh
    MAVLink 2 key, vehicles drop what is not signed with it."""
    if flavour not in FLAVOURS:
        raise ConfigError("flavour", f"must be one of {', '.join(FLAVOURS)}, got {flavour!r}")
    if not 1 <= vehicles <= MAX_VEHICLES:
        raise ConfigError("vehicles", f"must be 1..{MAX_VEHICLES}, got {vehicles}")
    folder = Path(workdir or tempfile.mkdtemp(prefix="enclose-sim-"))
    folder.mkdir(parents=True, exist_ok=True)
    key_file = folder / "signing.key" if signing else None
    key = write_key(key_file) if key_file is not None else None
    # The ports it binds, and the ones a client binds: a slot some process holds one of
    # anyway (a test's connection left open) is passed over for the next.
    with port_slot(held=lambda ports: ports_held(ports[:2 * vehicles])) as slot:
        listen, send = slot.ports.start, slot.ports.start + vehicles
        argv = [sys.executable, "-m", "deploy.commands.sim", "--vehicles", str(vehicles),
                "--flavour", flavour, "--host", HOST, "--base-port", str(listen),
                "--send-base-port", str(send)]
        argv += ["--signing-key", str(key_file)] if key_file is not None else []
        log_path = folder / "sim.log"
        with log_path.open("wb") as log:
            proc = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT)
        try:
            _wait_ready(proc, log_path)
            yield SimEndpoints(
                tuple(Vehicle(i + 1, listen + i, send + i) for i in range(vehicles)),
                flavour, key, key_file, proc.pid, log_path)
        finally:
            stop(proc)


def _wait_ready(proc: subprocess.Popen[bytes], log_path: Path) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while READY_LINE not in log_path.read_text(errors="replace"):
        if proc.poll() is not None or time.monotonic() > deadline:
            why = "exited" if proc.returncode is not None else "did not start"
            tail = log_path.read_text(errors="replace")[-2000:]
            raise SimulatorError(f"the simulator {why} (log {log_path}):\n{tail}")
        time.sleep(0.05)


def stop(proc: subprocess.Popen[bytes]) -> int:
    """SIGTERM by PID (the simulator prints its counts and exits), SIGKILL if it hangs."""
    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGTERM)
        try:
            proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(STOP_TIMEOUT_S)
    return int(proc.returncode)
