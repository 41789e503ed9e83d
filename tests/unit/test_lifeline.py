"""No process outlives its launcher (agents.shell.lifeline): every way the supervisor starts a
child (a fresh interpreter, a fork, a fork by the fork server), then a SIGKILLed launcher."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from deploy.procs.pids import ProcessId, identify, is_alive, signal_same

pytestmark = [pytest.mark.timeout(60), pytest.mark.realtime]

# A launcher that starts one child of each kind, stops one (a `pause` fault), prints
# their PIDs and is killed.
KILLED_LAUNCHER = """
import os, signal, sys, time
from pathlib import Path
from deploy.procs.supervisor import Supervisor
from deploy.procs.zygote import Zygote
sup = Supervisor(Path(sys.argv[1]))
sup.zygote = Zygote(["tests.child_proc"], Path(sys.argv[1]) / "zygote.log")
by_server = sup.start("follower-0", "tests.child_proc", ["sleep", "60"], fork=True)
sup.end_forks()
forked = sup.start("sim", "tests.child_proc", ["sleep", "60"], fork=True)
fresh = sup.start("recorder", "tests.child_proc", ["sleep", "60"])
paused = sup.start("follower-1", "tests.child_proc", ["ready", "60"])
deadline = time.monotonic() + 20.0  # paused once running, as a fault pauses it
while "ready" not in paused.log_path.read_text() and time.monotonic() < deadline:
    time.sleep(0.02)
os.kill(paused.pid, signal.SIGSTOP)
print(" ".join(str(c.pid) for c in (by_server, forked, fresh, paused)), flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""


def _wait_gone(procs: list[ProcessId], timeout_s: float) -> list[ProcessId]:
    deadline = time.monotonic() + timeout_s
    left = procs
    while left and time.monotonic() < deadline:
        time.sleep(0.05)
        left = [p for p in left if is_alive(p)]
    return left


def _alive_of(pids: list[int]) -> list[ProcessId]:
    return [i for i in (identify(p) for p in pids) if i.start_ticks is not None]


def test_children_of_every_kind_die_with_a_killed_launcher(tmp_path: Path) -> None:
    launcher = subprocess.Popen([sys.executable, "-c", KILLED_LAUNCHER, str(tmp_path)],
                                stdout=subprocess.PIPE, text=True)
    out, _ = launcher.communicate(timeout=40)
    assert launcher.returncode == -signal.SIGKILL
    pids = [int(p) for p in out.split()]
    assert len(pids) == 4, out
    children = _alive_of(pids)
    try:
        left = _wait_gone(children, 5.0)
        assert not left, f"still running after the launcher died: {left}"
    finally:
        for ident in children:
            signal_same(ident, signal.SIGKILL)


def test_a_child_whose_launcher_died_first_exits_at_once() -> None:
    # Our parent is the test process, not PID 1: binding to another PID must refuse.
    code = subprocess.run([sys.executable, "-c",
                           "from agents.shell.lifeline import die_with; die_with(1)"],
                          timeout=30, check=False).returncode
    assert code == 75  # EXIT_ORPHANED
    env_bound = subprocess.run(
        [sys.executable, "-c", "import os; from agents.shell.lifeline import die_with_launcher; "
         "die_with_launcher(); print(os.environ.get('ENCLOSE_LAUNCHER_PID'))"],
        env={"ENCLOSE_LAUNCHER_PID": "1", "PYTHONPATH": ":".join(sys.path)},
        capture_output=True, text=True, timeout=30, check=False)
    assert env_bound.returncode == 75
