"""`enclose run` end to end: real processes on loopback, real Zenoh, real MAVLink over UDP."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.integration.runs import pid_alive, spawned, wait_for

pytestmark = pytest.mark.integration


@contextlib.contextmanager
def launched(out: Path, *extra: str) -> Iterator[subprocess.Popen[str]]:
    """The launcher as a subprocess; whatever happens, it and every child are gone after."""
    argv = [sys.executable, "-m", "deploy.cli", "run", "--out", str(out), "--link-timeout", "60",
            *extra]
    with spawned(argv, out) as proc:
        yield proc


def assert_all_exited(out: Path) -> dict[str, int]:
    launch = json.loads((out / "launch.json").read_text())
    for name, proc in launch["processes"].items():
        assert not pid_alive(proc["pid"]), f"{name} (pid {proc['pid']}) still running"
    return {name: proc["exit_code"] for name, proc in launch["processes"].items()}


@pytest.mark.timeout(240)
def test_paper_case_forms_the_formation_and_every_process_exits_cleanly(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with launched(out, "--duration", "24") as proc:
        output, _ = proc.communicate(timeout=200)
    assert proc.returncode == 0, output
    codes = assert_all_exited(out)
    assert set(codes) == {"sim", "recorder", "follower-0", "follower-1", "follower-2",
                          "follower-3", "target-0", "target-1"}
    assert all(code == 0 for code in codes.values()), codes
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["radius_error_m"] < 0.0999
    assert metrics["angle_error"] < 0.0199
    assert metrics["estimator_error_m"] < 0.0999
    assert metrics["settle_time_s"] is not None and metrics["settle_time_s"] < 12.0
    assert metrics["command_jump_m_s"] < 0.5
    for name in ("series.csv", "recording.mcap", "performance.png", "trajectory.png",
                 "links.csv", "links.png"):
        assert (out / name).stat().st_size > 1000, name
    assert (out / "logs" / "follower-0.log").exists()
    # Piped: board lines, no escape codes, and the verdict at the end instead of metrics.json.
    assert "\x1b" not in output
    assert "processes 8/8 up" in output and "agents on UDP" in output
    tail = "\n".join(output.rstrip().splitlines()[-15:])
    assert "enclose run paper: INSIDE the paper's bounds" in tail, tail
    assert "none died, restarted or failed" in tail and f"files        {out}/" in tail


@pytest.mark.timeout(240)
def test_ctrl_c_stops_every_process_and_keeps_the_recording(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with launched(out, "--duration", "600") as proc:
        def running() -> bool:
            try:
                progress = json.loads((out / "progress.json").read_text())
            except (OSError, ValueError):
                return False
            return progress.get("state") == "running" and (progress.get("t_s") or 0.0) > 3.0

        wait_for(running, 120.0, "the run to be 3 s in")
        proc.send_signal(signal.SIGINT)
        output, _ = proc.communicate(timeout=150)
    assert proc.returncode == 130, output
    codes = assert_all_exited(out)
    assert codes["recorder"] == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["samples"] > 100
    assert (out / "recording.mcap").stat().st_size > 1000


@pytest.mark.timeout(240)
def test_a_dying_follower_fails_the_run_and_stops_the_rest(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with launched(out, "--duration", "600") as proc:
        pids_file = out / "logs" / "pids.json"
        wait_for(lambda: (out / "progress.json").exists(), 120.0, "the run to start")
        victim = json.loads(pids_file.read_text())["follower-2"]
        os.kill(victim, signal.SIGKILL)
        output, _ = proc.communicate(timeout=150)
    assert proc.returncode != 0
    assert "follower-2" in output
    codes = assert_all_exited(out)
    assert codes["follower-2"] == -signal.SIGKILL
