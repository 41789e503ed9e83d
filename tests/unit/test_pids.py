"""A PID is signalled only while it is still the process that was recorded (deploy.procs.pids):
a fake /proc reader for PID reuse, real children for the rest."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from deploy.procs.pids import (
    ProcessId,
    identify,
    is_alive,
    kill_run,
    read_pids,
    read_stat,
    signal_same,
    start_ticks,
    write_pids,
)
from deploy.procs.supervisor import Supervisor

pytestmark = pytest.mark.timeout(30)


def _stat(comm: str, ticks: int) -> str:
    # pid (comm) state ppid pgrp session tty tpgid flags minflt cminflt majflt cmajflt
    # utime stime cutime cstime priority nice threads itrealvalue starttime ...
    return f"77 ({comm}) S 1 77 77 0 -1 4194560 10 0 0 0 1 2 0 0 20 0 1 0 {ticks} 9 9\n"


def _sleeper() -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-m", "tests.child_proc", "sleep", "30"])


def _gone(proc: subprocess.Popen[bytes]) -> bool:
    try:
        proc.wait(5.0)
    except subprocess.TimeoutExpired:
        return False
    return True


def test_start_time_is_field_22_even_after_a_command_name_with_spaces_and_parens() -> None:
    assert start_ticks(77, lambda _pid: _stat("a) b (c", 123456)) == 123456
    assert start_ticks(77, lambda _pid: None) is None
    assert start_ticks(77, lambda _pid: "77 (x) S 1") is None
    me = start_ticks(os.getpid())
    assert me is not None and me == start_ticks(os.getpid())


@pytest.mark.realtime
def test_a_live_process_with_another_start_time_is_not_signalled() -> None:
    proc = _sleeper()
    try:
        real = identify(proc.pid)
        assert real.start_ticks is not None and is_alive(real)
        # The PID now names a later process (as after reuse): its start time differs.
        reused = ProcessId(proc.pid, real.start_ticks - 1)
        assert not signal_same(reused, signal.SIGKILL)
        assert not is_alive(reused)
        later = lambda pid: _stat("python", real.start_ticks + 500)  # noqa: E731
        assert not signal_same(real, signal.SIGKILL, later)  # a fake /proc says: another one
        assert proc.poll() is None  # nothing was sent
        assert not signal_same(ProcessId(proc.pid, None), signal.SIGKILL)  # never recorded
        assert signal_same(real, signal.SIGTERM)
        assert _gone(proc) and proc.returncode == -signal.SIGTERM
    finally:
        proc.kill()
        proc.wait()


@pytest.mark.realtime
def test_a_reaped_child_is_never_signalled_again() -> None:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    ident = identify(proc.pid)
    ticks = ident.start_ticks
    assert ticks is not None
    proc.wait()  # reaped: the PID is free, or soon another process's
    assert not is_alive(ident)
    assert not signal_same(ident, signal.SIGKILL)
    # Whatever lives at that PID now (a fake /proc: a process started later) is left alone.
    assert not signal_same(ident, signal.SIGKILL, lambda _pid: _stat("victim", ticks + 1))


def test_pids_file_round_trips_and_skips_what_is_not_an_entry(tmp_path: Path) -> None:
    ids = {"sim": ProcessId(10, 5), "follower-0": ProcessId(11, None)}
    write_pids(tmp_path, ids)
    assert read_pids(tmp_path) == ids
    (tmp_path / "pids.json").write_text(json.dumps(
        {"a": 12, "b": {"pid": "13", "start_ticks": 1}, "c": {"pid": 14},
         "d": {"pid": -1, "start_ticks": 1}, "e": {"pid": 15, "start_ticks": 2}}))
    assert read_pids(tmp_path) == {"e": ProcessId(15, 2)}
    (tmp_path / "pids.json").write_text("[1, 2]")
    assert read_pids(tmp_path) == {}
    assert read_pids(tmp_path / "nowhere") == {}


@pytest.mark.realtime
def test_the_supervisor_records_start_times_and_a_cleanup_kills_only_live_ones(
        tmp_path: Path) -> None:
    sup = Supervisor(tmp_path)
    try:
        live = sup.start("follower-0", "tests.child_proc", ["sleep", "30"])
        short = sup.start("follower-1", "tests.child_proc", ["exit", "0"])
        assert sup.wait([short], 20.0)  # exited and reaped by the supervisor
        recorded = read_pids(tmp_path)
        assert recorded["follower-0"] == identify(live.pid or 0)
        assert recorded["follower-0"].start_ticks == start_ticks(live.pid or 0, read_stat)
        assert kill_run(tmp_path) == ["follower-0"]
        assert sup.wait([live], 10.0) and live.poll() == -signal.SIGKILL
    finally:
        sup.stop_all(grace_s=1.0)

