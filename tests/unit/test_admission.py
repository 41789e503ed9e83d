"""The swarm tests' admission (tests/admission.py): what it counts, when it lets a test go."""

from __future__ import annotations

import fcntl
from pathlib import Path

import pytest

from deploy.report.cpu_load import TICKS_PER_S
from tests.admission import Gate, demand_cores, foreground_ticks

pytestmark = pytest.mark.timeout(30)


def _stat(pid: int, comm: str, utime: int, stime: int, nice: int, policy: int) -> str:
    # Fields 3.. after the command name: state, then 10 numbers up to utime (14), stime
    # (15), 3 more, nice (19), then up to policy (41).
    rest = ["S"] + ["0"] * 10 + [str(utime), str(stime)] + ["0"] * 3 + [str(nice)]
    rest += ["0"] * (38 - len(rest)) + [str(policy), "0", "0"]
    return f"{pid} ({comm}) " + " ".join(rest) + "\n"


def _proc(tmp_path: Path, rows: dict[int, str | None]) -> Path:
    for pid, text in rows.items():
        (tmp_path / str(pid)).mkdir()
        if text is not None:
            (tmp_path / str(pid) / "stat").write_text(text)
    (tmp_path / "self").mkdir()
    return tmp_path


def test_counts_normal_priority_processes_only(tmp_path: Path) -> None:
    proc = _proc(tmp_path, {
        10: _stat(10, "python", 100, 20, 0, 0),
        11: _stat(11, "odd ) name (x", 5, 5, -5, 1),   # a name with parentheses, SCHED_FIFO
        12: _stat(12, "unit tests", 900, 0, 0, 5),      # SCHED_IDLE: not counted
        13: _stat(13, "nice", 900, 0, 19, 0),           # niced to 19: not counted
        14: "14 (broken) S 1 2\n",                      # too short: skipped
        15: None,                                       # ended while read: skipped
    })
    assert foreground_ticks(proc) == {10: 120, 11: 10}


def test_demand_is_the_ticks_used_over_the_window() -> None:
    ticks = int(TICKS_PER_S)
    before = {1: 0, 2: 5 * ticks, 3: 7}  # 3 ends in the window: not counted
    after = {1: ticks, 2: 5 * ticks + ticks // 2, 4: ticks // 2}  # 4 started in it
    assert demand_cores(before, after, 2.0) == pytest.approx(1.0)
    assert demand_cores({1: 10}, {1: 10}, 1.0) == 0.0


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0
        self.slept: list[float] = []

    def now(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.slept.append(s)
        self.t += s


def test_waits_while_the_machine_is_full_then_admits(tmp_path: Path) -> None:
    clock, readings = Clock(), iter([1.9, 1.5, 1.2, 0.4])

    def measure(window_s: float) -> float:
        clock.t += window_s
        return next(readings)

    gate = Gate(threshold_cores=1.3, lock_file=tmp_path / "lock")
    waited, demand = gate.admit(measure, clock.now, clock.sleep, clock.now)
    assert demand == 1.2 and waited == pytest.approx(3.0)
    assert float((tmp_path / "lock").read_text()) == pytest.approx(clock.t)


def test_keeps_the_spacing_after_the_previous_admission(tmp_path: Path) -> None:
    clock = Clock()
    (tmp_path / "lock").write_text(f"{clock.t - 3.0}")  # admitted 3 s ago
    gate = Gate(threshold_cores=1.0, spacing_s=8.0, lock_file=tmp_path / "lock")
    waited, demand = gate.admit(lambda w: 0.1, clock.now, clock.sleep, clock.now)
    assert clock.slept == [pytest.approx(5.0)] and waited == pytest.approx(5.0)
    assert demand == 0.1


def test_gives_up_waiting_at_the_bound(tmp_path: Path) -> None:
    clock = Clock()

    def measure(window_s: float) -> float:
        clock.t += window_s
        return 2.0

    gate = Gate(threshold_cores=1.0, wait_max_s=10.0, lock_file=tmp_path / "lock")
    waited, demand = gate.admit(measure, clock.now, clock.sleep, clock.now)
    assert demand == 2.0 and 10.0 <= waited <= 11.0


def test_a_held_lock_is_waited_for_up_to_the_bound(tmp_path: Path) -> None:
    clock, lock_file = Clock(), tmp_path / "lock"
    with open(lock_file, "a+") as other:  # another worker being admitted
        fcntl.flock(other, fcntl.LOCK_EX)
        gate = Gate(threshold_cores=1.0, wait_max_s=5.0, lock_file=lock_file)
        waited, demand = gate.admit(lambda w: 0.0, clock.now, clock.sleep, clock.now)
    assert demand is None and waited >= 5.0
