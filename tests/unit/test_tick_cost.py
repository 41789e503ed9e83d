"""agents.shell.tick_cost: phase CPU between marks, and thread groups from a /proc task folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from agents.shell.tick_cost import ENV, PHASES, NoCost, TickCost, thread_cpu_ns, tick_cost


def task(tasks: Path, tid: int, comm: str, run_ns: int) -> None:
    folder = tasks / str(tid)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "comm").write_text(comm + "\n")
    (folder / "schedstat").write_text(f"{run_ns} 0 0\n")


def test_threads_are_grouped_by_name_and_the_loops_own_id(tmp_path: Path) -> None:
    task(tmp_path, 10, "python", 5_000)
    task(tmp_path, 11, "rx-0", 700)
    task(tmp_path, 12, "tx-0", 300)
    task(tmp_path, 13, "python", 40)  # a Python thread: the stall guard
    (tmp_path / "14").mkdir()  # a thread that ended while the folder was read
    assert thread_cpu_ns(tmp_path, main=10) == {"main": 5_000, "zenoh": 1_000, "other": 40}


def test_each_mark_charges_its_phase_from_begin_on(tmp_path: Path) -> None:
    now = [0]
    task(tmp_path, 1, "python", 1_000_000)
    task(tmp_path, 2, "net-0", 0)
    cost = TickCost(tmp_path, clock=lambda: now[0], main=1)
    cost.mark("wait")  # before begin: the start-up is not measured
    cost.begin()
    for _ in range(2):
        now[0] += 3_000
        cost.mark("wait")
        now[0] += 10_000
        cost.mark("receive")
        now[0] += 7_000
        cost.mark("law")
    task(tmp_path, 1, "python", 1_050_000)
    task(tmp_path, 2, "net-0", 8_000)
    counters = cost.counters()
    assert counters["cost_ticks"] == 2
    assert (counters["cost_us_wait"], counters["cost_us_receive"], counters["cost_us_law"]) \
        == (6, 20, 14)
    assert {counters[f"cost_us_{p}"] for p in PHASES if p not in ("wait", "receive", "law")} \
        == {0}
    assert (counters["cost_us_thread_main"], counters["cost_us_thread_zenoh"]) == (50, 8)


def test_off_unless_the_environment_asks(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(ENV, raising=False)
    off = tick_cost()
    off.begin()
    off.mark("law")
    assert isinstance(off, NoCost) and off.counters() == {}
    monkeypatch.setenv(ENV, "1")
    assert isinstance(tick_cost(), TickCost)
