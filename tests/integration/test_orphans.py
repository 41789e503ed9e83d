"""A SIGKILLed launcher leaves no process of its run behind (agents.shell.lifeline)."""

from __future__ import annotations

import signal
import sys
from pathlib import Path

import pytest

from deploy.procs.pids import ProcessId, is_alive, read_pids
from tests.integration.runs import spawned_run, wait_for

pytestmark = pytest.mark.integration
RUN = ("sim", "recorder", "target-0", "target-1",
       "follower-0", "follower-1", "follower-2", "follower-3")
GONE_WITHIN_S = 5.0


def _all_up(out: Path) -> bool:
    ids = read_pids(out / "logs")
    return all(name in ids and is_alive(ids[name]) for name in RUN)


def _left(ids: dict[str, ProcessId]) -> dict[str, ProcessId]:
    return {name: ident for name, ident in ids.items() if is_alive(ident)}


@pytest.mark.timeout(180)
def test_no_process_of_the_run_outlives_a_sigkilled_launcher(tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = [sys.executable, "-m", "deploy.cli", "run", "paper", "--out", str(out),
            "--duration", "60", "--link-timeout", "90", "--no-live", "--no-figures"]
    with spawned_run(argv, out) as launcher:  # kills any survivor by PID and start time
        # Every process started, not yet linked (the followers' vehicles take seconds to
        # take off): the moment the issue found the simulator and followers left running.
        wait_for(lambda: _all_up(out) or launcher.poll() is not None, 120.0,
                 "every process of the run to start")
        assert launcher.poll() is None, launcher.communicate()[0][-3000:]
        ids = read_pids(out / "logs")
        launcher.send_signal(signal.SIGKILL)
        launcher.wait(10)
        try:
            wait_for(lambda: not _left(ids), GONE_WITHIN_S, "the run's processes to die")
        except AssertionError:
            pytest.fail(f"left running {GONE_WITHIN_S} s after the launcher: {_left(ids)}")
    assert set(RUN) <= set(ids)
