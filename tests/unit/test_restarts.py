"""The launcher's restart policies, on real (tiny) child processes."""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest

from deploy.procs.restarts import RestartPolicy, Watchdog, how_it_ended
from deploy.procs.supervisor import Supervisor
from errors import DeployError

pytestmark = pytest.mark.timeout(30)


def poll_until(dog: Watchdog, ok: object, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not ok():  # type: ignore[operator]
        assert time.monotonic() < deadline, dog.events
        dog.check()
        time.sleep(0.02)


def test_policy_backoff_doubles_to_a_cap_and_is_validated() -> None:
    p = RestartPolicy()
    assert [p.delay_s(k) for k in range(5)] == [1.0, 2.0, 4.0, 8.0, 8.0]
    with pytest.raises(DeployError, match="--restart"):
        RestartPolicy("always")
    assert how_it_ended(-9) == {"exit_code": None, "signal": "SIGKILL"}
    assert how_it_ended(2) == {"exit_code": 2}


@pytest.mark.realtime
def test_on_failure_restarts_a_killed_follower_with_backoff_then_gives_up(tmp_path: Path) -> None:
    sup = Supervisor(tmp_path)
    try:
        sup.start("follower-0", "tests.child_proc", ["sleep", "30"])
        sup.start("follower-1", "tests.child_proc", ["sleep", "30"])
        victim = sup.start("follower-2", "tests.child_proc", ["sleep", "30"])
        dog = Watchdog(sup, RestartPolicy(backoff_s=0.1, max_restarts=1), time.monotonic())
        first_pid = victim.pid
        assert victim.proc is not None
        victim.proc.send_signal(signal.SIGKILL)
        poll_until(dog, lambda: victim.restarts == 1 and victim.poll() is None)
        assert victim.pid != first_pid
        assert [e["event"] for e in dog.events] == ["died", "restarted"]
        assert dog.events[0]["signal"] == "SIGKILL" and dog.events[0]["restart_in_s"] == 0.1
        victim.proc.send_signal(signal.SIGKILL)
        poll_until(dog, lambda: len(dog.events) == 3)
        assert dog.events[2]["restart"] == "limit reached"
        dog.check()
        assert victim.poll() == -9 and dog.handled(victim) and dog.deaths == 2
    finally:
        sup.stop_all(grace_s=1.0)


@pytest.mark.realtime
def test_never_leaves_it_dead_and_a_clean_exit_is_no_death(tmp_path: Path) -> None:
    sup = Supervisor(tmp_path)
    try:
        sup.start("follower-0", "tests.child_proc", ["sleep", "30"])
        sup.start("follower-1", "tests.child_proc", ["exit", "0"])
        sup.start("target-0", "tests.child_proc", ["exit", "0"])
        bad = sup.start("follower-2", "tests.child_proc", ["exit", "4"])
        # Done before our clock says the run is over: not lost, the run goes on.
        sup.start("follower-3", "tests.child_proc", ["exit", "0"])
        dog = Watchdog(sup, RestartPolicy("never"), time.monotonic())
        poll_until(dog, lambda: dog.events)
        time.sleep(0.3)
        dog.check()
        assert dog.events == [
            {"t_s": dog.events[0]["t_s"], "process": "follower-2", "event": "died",
             "exit_code": 4, "restart": "never"}
        ]
        assert bad.restarts == 0
    finally:
        sup.stop_all(grace_s=1.0)


@pytest.mark.realtime
def test_the_run_aborts_when_the_simulator_or_all_but_one_follower_die(tmp_path: Path) -> None:
    sup = Supervisor(tmp_path)
    try:
        sup.start("follower-0", "tests.child_proc", ["sleep", "30"])
        sup.start("follower-1", "tests.child_proc", ["exit", "1"])
        dog = Watchdog(sup, RestartPolicy("never"), time.monotonic())
        with pytest.raises(DeployError, match="follower"):
            poll_until(dog, lambda: False)
    finally:
        sup.stop_all(grace_s=1.0)
    sup = Supervisor(tmp_path / "2")
    try:
        sup.start("follower-0", "tests.child_proc", ["sleep", "30"])
        sup.start("follower-1", "tests.child_proc", ["sleep", "30"])
        sup.start("sim", "tests.child_proc", ["exit", "1"])
        dog = Watchdog(sup, RestartPolicy(max_restarts=0), time.monotonic())
        with pytest.raises(DeployError, match="simulator"):
            poll_until(dog, lambda: False)
    finally:
        sup.stop_all(grace_s=1.0)


@pytest.mark.realtime
def test_rebase_restamps_start_up_events_from_the_start_and_keeps_restart_counts(
    tmp_path: Path,
) -> None:
    sup = Supervisor(tmp_path)
    try:
        sup.start("follower-0", "tests.child_proc", ["sleep", "30"])
        sup.start("follower-1", "tests.child_proc", ["sleep", "30"])
        victim = sup.start("follower-2", "tests.child_proc", ["exit", "2"])
        launched_at = time.monotonic()
        dog = Watchdog(sup, RestartPolicy(backoff_s=0.05, max_restarts=1), launched_at)
        poll_until(dog, lambda: len(dog.events) == 3)  # died, restarted, died for good
        assert dog.events[2]["restart"] == "limit reached"
        hooked: list[str] = []
        start = launched_at + 100.0
        dog.rebase(start, RestartPolicy(backoff_s=0.05, max_restarts=3), hooked.append)
        # a death seen in the first poll is at t_s 0.0 before the rebase, -100.0 after it
        assert all(-100.0 <= e["t_s"] < -90.0 for e in dog.events), dog.events
        assert victim.restarts == 1 and dog.policy.max_restarts == 3 and dog.t0_s == start
    finally:
        sup.stop_all(grace_s=1.0)


@pytest.mark.realtime
def test_a_death_not_yet_checked_is_not_dead_for_good(tmp_path: Path) -> None:
    """The launcher ends a launch on a process dead for good; one that died after the
    watchdog's last look may still be restarted (a start-up race that ended a ring64
    launch though the policy would have restarted the process)."""
    sup = Supervisor(tmp_path)
    try:
        sup.start("follower-0", "tests.child_proc", ["sleep", "30"])
        sup.start("follower-1", "tests.child_proc", ["sleep", "30"])
        dog = Watchdog(sup, RestartPolicy(backoff_s=5.0), time.monotonic())
        victim = sup.start("follower-2", "tests.child_proc", ["exit", "2"])
        deadline = time.monotonic() + 10.0
        while victim.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert victim.poll() == 2 and dog.dead_for_good() == []  # dead, not yet seen
        dog.check()
        assert dog.pending and dog.dead_for_good() == []  # seen: a restart is due
        never = Watchdog(sup, RestartPolicy("never"), time.monotonic())
        never.check()
        assert never.dead_for_good() == [victim]
    finally:
        sup.stop_all(grace_s=1.0)
