"""Start `enclose sim` as a real subprocess on unusual loopback ports; stop it by PID."""

from __future__ import annotations

import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from agents.mavlink.wire import new_codec
from agents.mavlink.wire_decode import decode_datagram

HOST = "127.0.0.1"


def free_port_block(count: int) -> int:
    """A base port such that base..base+count-1 are free for UDP right now."""
    for _ in range(200):
        base = random.randrange(21000, 29000)
        socks: list[socket.socket] = []
        try:
            for k in range(count):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(s)
                s.bind((HOST, base + k))
            return base
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError("no free UDP port block")


@dataclass
class SimProcess:
    proc: subprocess.Popen[bytes]
    listen_base: int
    send_base: int
    log_path: Path

    def output(self) -> str:
        return self.log_path.read_text(errors="replace")

    def stop(self, timeout_s: float = 5.0) -> int:
        """SIGTERM by PID, then SIGKILL if it does not exit; returns the exit code."""
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                os.kill(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout_s)
        return int(self.proc.returncode)


def start_sim(*extra: str, vehicles: int = 1, console_script: bool = False) -> SimProcess:
    listen_base = free_port_block(vehicles)
    send_base = free_port_block(vehicles)
    log = Path(tempfile.mkstemp(prefix="enclose-sim-", suffix=".log")[1])
    if console_script:
        cmd = [str(Path(sys.executable).with_name("enclose")), "sim"]
    else:
        cmd = [sys.executable, "-m", "deploy.commands.sim"]
    cmd += ["--vehicles", str(vehicles), "--base-port", str(listen_base),
            "--send-base-port", str(send_base), *extra]
    with log.open("wb") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT)
    return SimProcess(proc, listen_base, send_base, log)


class PlainClient:
    """A bare pymavlink client (not the project's adapter), as a GCS or SDK would be."""

    def __init__(self, local_port: int, vehicle_port: int, target_sysid: int = 1) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((HOST, local_port))
        self.sock.settimeout(0.02)
        self.mav = new_codec(255, 190)
        self.vehicle = (HOST, vehicle_port)
        self.sysid = target_sysid
        self.last: dict[str, object] = {}
        self.acks: list[tuple[int, int]] = []
        self.received: list[str] = []
        self.history: list[object] = []  # every message, when several share one datagram

    def close(self) -> None:
        self.sock.close()

    def send(self, msg: object) -> None:
        self.sock.sendto(msg.pack(self.mav), self.vehicle)  # type: ignore[attr-defined]

    def send_raw(self, data: bytes) -> None:
        self.sock.sendto(data, self.vehicle)

    def pump(self) -> None:
        try:
            data, _ = self.sock.recvfrom(65535)
        except TimeoutError:
            return
        self._take(data)

    def _take(self, data: bytes) -> None:
        for m in decode_datagram(self.mav, data).messages:
            self.last[m.get_type()] = m
            self.received.append(m.get_type())
            self.history.append(m)
            if m.get_type() == "COMMAND_ACK":
                self.acks.append((m.command, m.result))

    def drain(self) -> None:
        """Process every datagram already queued (so `last` is current), without waiting."""
        self.sock.settimeout(0.0)
        try:
            while True:
                try:
                    data, _ = self.sock.recvfrom(65535)
                except (BlockingIOError, TimeoutError):
                    return
                self._take(data)
        finally:
            self.sock.settimeout(0.02)

    def until(self, ok: Callable[[], bool], timeout_s: float, what: str,
              every: Callable[[], None] | None = None) -> None:
        deadline = time.monotonic() + timeout_s
        while not ok():
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out waiting for {what}")
            if every is not None:
                every()
            self.pump()

    def command(self, cmd: int, *params: float, timeout_s: float = 2.0) -> int:
        p = list(params) + [0.0] * (7 - len(params))
        self.acks.clear()
        self.send(self.mav.command_long_encode(self.sysid, 1, cmd, 0, *p))
        self.until(lambda: any(c == cmd for c, _ in self.acks), timeout_s, f"ACK of {cmd}")
        return next(r for c, r in self.acks if c == cmd)


def message_outcomes(output: str) -> dict[str, int]:
    """The simulator's closing "sim messages:" line as {"TYPE:outcome": count}."""
    for line in output.splitlines():
        if line.startswith("sim messages:"):
            pairs = (item.rsplit("=", 1) for item in line.split(":", 1)[1].split())
            return {k: int(v) for k, v in pairs}
    raise AssertionError(f"no 'sim messages:' line in simulator output:\n{output[-2000:]}")


def assert_all_answered(output: str) -> dict[str, int]:
    """Every message a client sent was answered, handled or ignored by design; none failed."""
    outcomes = message_outcomes(output)
    bad = {k: v for k, v in outcomes.items()
           if k.endswith((":unhandled", ":failed"))}
    assert not bad, f"messages left unanswered or failed: {bad}"
    return outcomes
