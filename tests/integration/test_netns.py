"""`enclose run --netns`: a real network namespace with real kernel packet loss (root only)."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from deploy.netns.namespace import TABLE, destroy, lossy_namespace, namespaces, probe
from deploy.procs.pids import is_alive, read_pids
from tests.integration.runs import spawned

pytestmark = pytest.mark.integration

UDP_COUNT = 3000
UDP_PROBE = f"""
import socket
rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 23)
rx.bind(("127.0.0.1", 0))
tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
got = 0
rx.settimeout(0.3)
for k in range({UDP_COUNT}):
    tx.sendto(b"x" * 64, rx.getsockname())
    if k % 50 == 49:  # drain as we go: a full receive buffer would be loss of another kind
        rx.setblocking(False)
        while True:
            try:
                rx.recv(128)
            except BlockingIOError:
                break
            got += 1
        rx.settimeout(0.3)
while True:
    try:
        rx.recv(128)
    except TimeoutError:
        break
    got += 1
print(got)
"""


@pytest.fixture(scope="module", autouse=True)
def netns_available() -> None:
    reason = probe()
    if reason is not None:
        pytest.skip(f"no network namespace here: {reason}")


def in_ns(name: str, *argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["ip", "netns", "exec", name, *argv], capture_output=True, text=True,
                          timeout=60, check=False)


@pytest.mark.timeout(60)
def test_namespace_table_and_processes_are_removed_even_when_the_body_raises() -> None:
    name = f"enclose-{os.getpid()}-raise"
    sleeper: subprocess.Popen[bytes] | None = None
    try:
        with pytest.raises(RuntimeError, match="boom"), lossy_namespace(0.1, name=name) as ns:
            assert name in namespaces()
            assert TABLE in in_ns(name, "nft", "list", "tables").stdout
            assert "UP" in in_ns(name, "ip", "link", "show", "lo").stdout
            sleeper = subprocess.Popen(ns.exec_argv(["sleep", "300"]))
            deadline = time.monotonic() + 10
            while sleeper.pid not in ns.pids() and time.monotonic() < deadline:
                time.sleep(0.05)
            assert sleeper.pid in ns.pids()
            raise RuntimeError("boom")
        assert name not in namespaces()
        assert sleeper is not None and sleeper.wait(10) is not None
        assert TABLE not in subprocess.run(["nft", "list", "tables"], capture_output=True,
                                           text=True, timeout=10, check=True).stdout
    finally:
        if sleeper is not None and sleeper.poll() is None:
            sleeper.kill()
            sleeper.wait()
        if name in namespaces():
            destroy(name)


@pytest.mark.timeout(60)
def test_a_stale_namespace_of_a_dead_launcher_is_removed_at_the_next_start() -> None:
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait(10)
    stale = f"enclose-{gone.pid}"
    subprocess.run(["ip", "netns", "add", stale], check=True, timeout=10)
    try:
        with lossy_namespace(0.0, name=f"enclose-{os.getpid()}-fresh"):
            assert stale not in namespaces()
    finally:
        if stale in namespaces():
            destroy(stale)


@pytest.mark.timeout(90)
def test_twenty_percent_of_udp_datagrams_on_loopback_are_really_lost() -> None:
    with lossy_namespace(0.2, name=f"enclose-{os.getpid()}-udp") as ns:
        done = in_ns(ns.name, sys.executable, "-c", UDP_PROBE)
        assert done.returncode == 0, done.stderr
        counters = ns.counters()
    loss = 1.0 - int(done.stdout) / UDP_COUNT
    assert 0.15 < loss < 0.25, loss
    assert counters["packets_seen"] >= UDP_COUNT
    assert 0.15 < counters["packets_dropped"] / counters["packets_seen"] < 0.25, counters


@contextlib.contextmanager
def launched(out: Path, *extra: str) -> Iterator[subprocess.Popen[str]]:
    argv = [sys.executable, "-m", "deploy.cli", "run", "--netns", "--out", str(out),
            "--link-timeout", "60", "--no-figures", *extra]
    with spawned(argv, out) as proc:
        try:
            yield proc
        finally:
            for name in namespaces():
                if name == f"enclose-{proc.pid}":
                    destroy(name)


def assert_nothing_left(out: Path, launcher_pid: int) -> None:
    assert f"enclose-{launcher_pid}" not in namespaces()
    for name, ident in read_pids(out / "logs").items():
        assert not is_alive(ident), f"{name} (pid {ident.pid}) still running"


@pytest.mark.timeout(240)
def test_a_run_in_a_lossy_namespace_completes_and_leaves_nothing_behind(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with launched(out, "--os-loss", "0.05", "--duration", "12") as proc:
        output, _ = proc.communicate(timeout=200)
    assert proc.returncode == 0, output
    assert_nothing_left(out, proc.pid)
    netns = json.loads((out / "netns.json").read_text())
    assert netns["namespace"] == f"enclose-{proc.pid}"
    assert 0.03 < netns["measured_loss"] < 0.07, netns
    assert netns["mavlink_lossless"] is True
    assert json.loads((out / "metrics.json").read_text())["samples"] > 100


@pytest.mark.timeout(240)
def test_ctrl_c_inside_the_namespace_stops_the_run_and_removes_the_namespace(
    tmp_path: Path,
) -> None:
    out = tmp_path / "run"
    with launched(out, "--os-loss", "0.05", "--duration", "600") as proc:
        deadline = time.monotonic() + 120
        while not (out / "progress.json").exists():
            assert proc.poll() is None and time.monotonic() < deadline, "run did not start"
            time.sleep(0.1)
        assert f"enclose-{proc.pid}" in namespaces()
        proc.send_signal(signal.SIGINT)
        output, _ = proc.communicate(timeout=150)
    assert proc.returncode == 130, output
    assert_nothing_left(out, proc.pid)
    assert (out / "recording.mcap").exists()
