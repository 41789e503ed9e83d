"""Done-when of issue 10: kill -9 of the paper's follower 1 (process follower-0) 20 s into
the run (the issue's is 30 s; the ring is steady from ~10 s).  Default policy: it is
restarted, takes its vehicle over and the ring of 4 is inside the paper's bounds over the
last 20 s.  `--restart never`: the 3 survivors re-form
a steady ring at the desired radius over the last 20 s.

The run is 60 s (the issue's is 100 s): either ring is back inside the bounds ~10 s after
the kill (errors under 0.03 m, then ~0.01 m), so the last 20 s start 10 s after that and
judge the same steady ring as the last 20 s of 100 would, 40 s sooner."""

from __future__ import annotations

import json
import signal
import sys
from pathlib import Path
from typing import Any

import pytest

from agents.loading.scenario_file import load_scenario
from agents.membership.ring_accuracy import PhaseErrors, phase_errors
from deploy.procs.pids import read_pids, signal_same
from deploy.report.rundir import read_series
from tests.integration.real_time import judged
from tests.integration.runs import pid_alive, spawned_run, wait_for

pytestmark = pytest.mark.integration
DURATION_S, KILL_AT_S, LAST_S = 60.0, 20.0, 20.0


def progress_t_s(out: Path) -> float:
    try:
        return float(json.loads((out / "progress.json").read_text()).get("t_s") or 0.0)
    except (OSError, ValueError):
        return 0.0


def run_with_kill(out: Path, *extra: str) -> tuple[int, str, dict[str, Any]]:
    argv = [sys.executable, "-m", "deploy.cli", "run", "--out", str(out), "--link-timeout", "60",
            "--duration", str(DURATION_S), "--estimator", "robust", "--no-figures", *extra]
    with spawned_run(argv, out) as proc:
        wait_for(lambda: progress_t_s(out) >= KILL_AT_S, 150.0, f"the run to be {KILL_AT_S} s in")
        assert signal_same(read_pids(out / "logs")["follower-0"], signal.SIGKILL)
        output, _ = proc.communicate(timeout=DURATION_S + 120.0)
    launch = json.loads((out / "launch.json").read_text())
    for name, p in launch["processes"].items():
        assert not pid_alive(p["pid"]), f"{name} (pid {p['pid']}) still running"
    return proc.returncode, output, launch


def last_window(out: Path, members: list[int]) -> PhaseErrors:
    scenario = load_scenario("paper")
    series = read_series(out / "series.csv", scenario.n, scenario.m)
    end = float(series.t_s[-1])
    assert end > DURATION_S - 1.0, end
    return phase_errors(series, scenario, members, end - LAST_S, end)


@pytest.mark.timeout(300)
def test_a_killed_follower_is_restarted_and_the_ring_of_four_is_in_bounds(tmp_path: Path) -> None:
    out = tmp_path / "run"
    code, output, launch = run_with_kill(out)
    assert code == 3, output  # the run went to its end, and says something died
    died, restarted = launch["events"][:2]
    assert died["process"] == "follower-0" and died["signal"] == "SIGKILL"
    assert restarted["event"] == "restarted" and launch["processes"]["follower-0"]["restarts"] == 1
    assert launch["processes"]["follower-0"]["exit_code"] == 0
    e = last_window(out, [0, 1, 2, 3])
    with judged(out):
        assert e.estimator_error_m < 0.0999, e
        assert e.radius_error_m < 0.0999, e
        assert e.angle_error < 0.0199, e


@pytest.mark.timeout(300)
def test_with_restart_never_the_three_survivors_form_a_steady_ring(tmp_path: Path) -> None:
    out = tmp_path / "run"
    code, output, launch = run_with_kill(out, "--restart", "never")
    assert code == 3, output
    assert launch["events"] == [
        {**launch["events"][0], "process": "follower-0", "event": "died", "restart": "never"}
    ]
    e = last_window(out, [1, 2, 3])
    with judged(out):
        assert e.radius_error_m < 0.0999, e
        assert e.estimator_error_m < 0.0999, e
        assert e.angle_error < 0.0199, e  # the re-formed spacing: 90, 90, 180 deg
    assert (out / "metrics.json").exists() and (out / "recording.mcap").stat().st_size > 1000
