"""Scripted faults: validated with errors naming the field, executed on real child processes."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from agents.follower.lie import begin_signal, end_signal
from agents.loading.scenario_file import parse_scenario
from agents.scenario.faults import FaultSpec, parse_fault_flag, parse_faults
from deploy.launch.fault_injector import FaultRunner
from deploy.procs.supervisor import Supervisor
from errors import ScenarioError

pytestmark = pytest.mark.timeout(30)
BASE = (
    "beta_m_s = 1.0\n[pattern]\nrho_d_m = 8.0\n"
    "[[followers]]\npos_m = [10.0, 0.0]\n[[followers]]\npos_m = [-10.0, 0.0]\n"
    '[[targets]]\npos_m = [0.0, 0.0]\nprofile = "constant"\nobserved_by = [1]\n'
)


def test_lie_table() -> None:
    s = parse_scenario(BASE + '[[faults]]\nat_s = 5\naction = "lie"\ntarget = "follower-2"\n'
                       'duration_s = 30\nmode = "bound"\n')
    assert s.faults == (FaultSpec(5.0, "lie", "follower-1", 30.0, "bound"),)


@pytest.mark.realtime
def test_runner_lies_by_signal(tmp_path: Path) -> None:
    """A lie is the process's own: the launcher only signals its start and its end."""
    sup = Supervisor(tmp_path)
    try:
        a = sup.start("follower-0", "tests.child_proc", ["sleep", "30"])
        sent: list[int] = []
        run = FaultRunner(sup, (FaultSpec(0.0, "lie", "follower-0", 0.1, "walk"),),
                          time.monotonic(), [])
        run._signal = lambda _child, signum: sent.append(signum)  # type: ignore[method-assign]
        deadline = time.monotonic() + 5.0
        while len(sent) < 2:
            assert time.monotonic() < deadline, sent
            run.check()
            time.sleep(0.01)
        assert sent == [begin_signal("walk"), end_signal()] and a.poll() is None
        assert [e["event"] for e in run.events] == ["fault", "lie ended"]
        assert run.events[0]["mode"] == "walk"
    finally:
        sup.stop_all(grace_s=1.0)


def test_faults_table_is_parsed_sorted_and_one_based() -> None:
    s = parse_scenario(
        BASE + '[[faults]]\nat_s = 30\naction = "pause"\ntarget = "follower-2"\nduration_s = 2\n'
        '[[faults]]\nat_s = 10\naction = "kill"\ntarget = "follower-1"\n'
    )
    assert s.faults == (FaultSpec(10.0, "kill", "follower-0"), FaultSpec(30.0, "pause",
                                                                         "follower-1", 2.0))


@pytest.mark.parametrize(
    ("table", "field"),
    [
        ({"at_s": 1, "action": "explode", "target": "follower-1"}, r"faults\[0\]\.action"),
        ({"action": "kill", "target": "follower-1"}, r"faults\[0\]\.at_s"),
        ({"at_s": -1, "action": "kill", "target": "follower-1"}, r"faults\[0\]\.at_s"),
        ({"at_s": 1, "action": "kill", "target": "follower-3"}, r"faults\[0\]\.target"),
        ({"at_s": 1, "action": "kill", "target": "sim-0"}, r"faults\[0\]\.target"),
        ({"at_s": 1, "action": "pause", "target": "target-1"}, r"faults\[0\]\.duration_s"),
        ({"at_s": 1, "action": "kill", "target": "recorder", "when": 2}, r"faults\[0\]\.when"),
        ({"at_s": 1, "action": "lie", "target": "follower-1", "duration_s": 5},
         r"faults\[0\]\.mode"),
        ({"at_s": 1, "action": "lie", "target": "follower-1", "duration_s": 5, "mode": "loud"},
         r"faults\[0\]\.mode"),
        ({"at_s": 1, "action": "lie", "target": "target-1", "duration_s": 5, "mode": "offset"},
         r"faults\[0\]\.target"),
        ({"at_s": 1, "action": "lie", "target": "follower-1", "mode": "walk"},
         r"faults\[0\]\.duration_s"),
        ({"at_s": 1, "action": "lie", "target": "follower-1", "mode": "walk", "duration_s": 0},
         r"faults\[0\]\.duration_s"),
        ({"at_s": 1, "action": "kill", "target": "follower-1", "mode": "offset"},
         r"faults\[0\]\.mode"),
    ],
)
def test_bad_faults_name_the_field(table: dict[str, object], field: str) -> None:
    with pytest.raises(ScenarioError, match=field):
        parse_faults([table], 2, 1)


def test_fault_flag() -> None:
    assert parse_fault_flag("30:kill:follower-1", 4, 2) == FaultSpec(30.0, "kill", "follower-0")
    assert parse_fault_flag("5:leave:follower-4:3", 4, 2) == FaultSpec(5.0, "leave", "follower-3",
                                                                       3.0)
    assert parse_fault_flag("none", 4, 2) is None
    assert parse_fault_flag("20:lie:follower-2:30:stale", 4, 2) == FaultSpec(
        20.0, "lie", "follower-1", 30.0, "stale")
    with pytest.raises(ScenarioError, match=r"--fault\.mode"):
        parse_fault_flag("20:lie:follower-2:30", 4, 2)
    with pytest.raises(ScenarioError, match="--fault"):
        parse_fault_flag("30:kill", 4, 2)


def state(pid: int | None) -> str:
    return Path(f"/proc/{pid}/stat").read_text().split(")")[1].split()[0]


@pytest.mark.realtime
def test_runner_pauses_resumes_restarts_and_kills(tmp_path: Path) -> None:
    sup = Supervisor(tmp_path)
    try:
        a = sup.start("follower-0", "tests.child_proc", ["sleep", "30"])
        b = sup.start("follower-1", "tests.child_proc", ["sleep", "30"])
        c = sup.start("target-0", "tests.child_proc", ["sleep", "30"])
        faults = (FaultSpec(0.0, "pause", "follower-0", 0.3), FaultSpec(0.0, "restart",
                  "follower-1", 0.2), FaultSpec(0.1, "kill", "target-0"))
        events: list[dict[str, object]] = []
        run = FaultRunner(sup, faults, time.monotonic(), events)
        first_b = b.pid
        run.check()
        deadline = time.monotonic() + 2.0
        while state(a.pid) != "T":  # SIGSTOP lands asynchronously
            assert time.monotonic() < deadline, state(a.pid)
            time.sleep(0.005)
        deadline = time.monotonic() + 10.0
        while run._todo and time.monotonic() < deadline:
            run.check()
            time.sleep(0.02)
        assert state(a.pid) in ("S", "R") and b.pid != first_b and b.poll() is None
        assert c.poll() == -9
        kinds = [(e["process"], e["event"]) for e in events]
        assert ("follower-0", "resumed") in kinds and ("follower-1", "started") in kinds
        assert kinds[0] == ("follower-0", "fault")
    finally:
        sup.stop_all(grace_s=1.0)
