"""tests/integration/real_time.py: an accuracy failure stands unless the run's own record
says its machine lost real time."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.integration.real_time import NotJudged, judged, lost_real_time

pytestmark = pytest.mark.timeout(30)


def _run(tmp_path: Path, sim_pct: float | None, followers_pct: float | None) -> Path:
    ticks = {"sim_overrun_pct": sim_pct, "overrun_pct": followers_pct}
    load = {"ticks": {k: v for k, v in ticks.items() if v is not None},
            "machine_busy_pct": 97.0, "load_1min": 9.5}
    (tmp_path / "launch.json").write_text(json.dumps({"load": load}))
    return tmp_path


def test_a_failure_on_a_run_that_kept_real_time_stands(tmp_path: Path) -> None:
    run = _run(tmp_path, 0.5, 0.02)
    assert lost_real_time(run) is None
    with pytest.raises(AssertionError, match="radius"), judged(run):
        raise AssertionError("radius 0.3")


@pytest.mark.parametrize(("sim", "followers"), [(8.5, 0.4), (0.2, 1.5), (47.0, None)])
def test_a_failure_on_a_run_that_lost_real_time_is_a_warning(
        tmp_path: Path, sim: float, followers: float | None) -> None:
    run = _run(tmp_path, sim, followers)
    reason = lost_real_time(run)
    assert reason is not None and f"{sim} %" in reason and "97.0 % busy" in reason
    with pytest.warns(NotJudged, match="not judged.*radius 0.3"), judged(run):
        raise AssertionError("radius 0.3")


def test_a_pass_is_a_pass_however_late(tmp_path: Path) -> None:
    run = _run(tmp_path, 60.0, 5.0)
    with judged(run):
        assert 0.01 < 0.0999


@pytest.mark.parametrize("text", [None, "not json", json.dumps({"load": None})])
def test_a_run_without_a_record_of_its_ticks_is_judged(tmp_path: Path, text: str | None) -> None:
    if text is not None:
        (tmp_path / "launch.json").write_text(text)
    assert lost_real_time(tmp_path) is None
    with pytest.raises(AssertionError), judged(tmp_path):
        raise AssertionError("estimator 0.2")


def test_other_errors_pass_through(tmp_path: Path) -> None:
    run = _run(tmp_path, 60.0, 5.0)
    with pytest.raises(KeyError), judged(run):
        raise KeyError("acks_own")


def _loaded(tmp_path: Path, busy_pct: float, load_1min: float,
            cpu_pct: dict[str, float]) -> Path:
    load = {"ticks": {"sim_overrun_pct": 9.0, "overrun_pct": 0.1}, "machine_busy_pct": busy_pct,
            "load_1min": load_1min, "cores": 2, "process_cpu_pct": cpu_pct}
    (tmp_path / "launch.json").write_text(json.dumps({"load": load}))
    return tmp_path


def test_late_on_a_machine_with_room_is_judged(tmp_path: Path) -> None:
    run = _loaded(tmp_path, 35.0, 1.2, {"sim": 30.0, "follower-0": 9.0})
    assert lost_real_time(run) is None
    with pytest.raises(AssertionError, match="radius"), judged(run):
        raise AssertionError("radius 0.3")


def test_late_behind_a_process_of_its_own_at_a_core_is_judged(tmp_path: Path) -> None:
    run = _loaded(tmp_path, 98.0, 12.0, {"sim": 97.5, "follower-0": 9.0})
    assert lost_real_time(run) is None


@pytest.mark.parametrize(("busy", "load_1min"), [(35.0, 4.0), (76.6, 1.5), (99.0, 10.5)])
def test_late_on_a_busy_or_queued_machine_is_not_judged(
        tmp_path: Path, busy: float, load_1min: float) -> None:
    run = _loaded(tmp_path, busy, load_1min, {"sim": 16.5, "recorder": 13.4})
    assert lost_real_time(run) is not None
