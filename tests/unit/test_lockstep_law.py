"""The generic lock-step path: any law through the interface, in one process.

The paper's law through it against the paper's compiled engine (agents.lockstep.engine):
not bit-identical, because the generic path gives each law its neighbours' messages of
the previous step (extrapolated by their rates, as in flight) and the targets' velocity
through the platform's filter, where the compiled engine uses the same step's estimates
and exact finite differences.  Measured on the paper's case, 20 s at 50 Hz: metrics within
0.5 % of each other, steady-state estimates within 1.4e-6 m; ring16 (the velocity stage,
per-link fields), 60 s: within 3.1 % (the angle error; the others 1.7 %) and 1.8e-4 m.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from agents.analysis.metrics import compute_metrics, error_series
from agents.analysis.timeseries import RunSeries
from agents.law.interface import Inputs, Law, Output, Sample, Setup
from agents.loading.law_loader import make_law
from agents.loading.scenario_file import load_scenario
from agents.lockstep.any_law import simulate_law
from agents.lockstep.engine import simulate_lockstep
from agents.membership.follower_place import setup_for
from agents.scenario.model import Scenario
from deploy.cli import main

pytestmark = pytest.mark.timeout(120)

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "simple_law" / "simple.toml"


def metrics(scenario: Scenario, series: RunSeries, duration_s: float) -> dict[str, Any]:
    errors = error_series(series, scenario.successor, np.asarray(scenario.pattern.angles_rad),
                          scenario.pattern.rho_d_m)
    return compute_metrics(series, errors, duration_s / 2, scenario.run.eps_rho_m,
                           scenario.run.eps_delta).as_dict()


def lead_free(scenario: Scenario) -> Scenario:
    return dataclasses.replace(scenario, gains=dataclasses.replace(scenario.gains, lead_s=0.0))


@pytest.mark.parametrize(("name", "duration_s", "rel", "est_m"),
                         [("paper", 20.0, 0.005, 1e-5), ("ring16", 60.0, 0.05, 1e-3)])
def test_the_papers_law_through_the_interface_agrees_with_its_compiled_engine(
        name: str, duration_s: float, rel: float, est_m: float) -> None:
    scenario = load_scenario(name)
    dt = 1.0 / scenario.run.rate_hz
    run = simulate_law(scenario, make_law(lead_free(scenario)), dt, duration_s)
    fast = simulate_lockstep(scenario, dt, duration_s)
    assert run.law_failures == 0
    generic, compiled = metrics(scenario, run.series, duration_s), metrics(
        scenario, fast, duration_s)
    for key in ("estimator_error_m", "radius_error_m", "angle_error"):
        assert generic[key] == pytest.approx(compiled[key], rel=rel), key
    steady = len(fast.t_s) // 2
    gap = np.abs(run.series.estimate_m - fast.estimate_m)[steady:].max()
    assert gap < est_m
    assert run.series.t_s.shape == fast.t_s.shape
    assert np.array_equal(run.series.target_pos_m, fast.target_pos_m)


def test_the_example_law_encloses_the_papers_targets_in_lock_step() -> None:
    scenario = load_scenario(EXAMPLE)
    run = simulate_law(scenario, make_law(scenario), scenario.run.dt_s, 60.0)
    got = metrics(scenario, run.series, 60.0)
    # Its plain consensus tracks with a standing error (0.026 m over 200 s): inside 0.05.
    assert run.law_failures == 0 and got["estimator_error_m"] < 0.05
    assert got["radius_error_m"] < 0.05 and got["angle_error"] < 0.01


class Flaky(Law[int]):
    """At steps of 0.1 s: raises at every 10th (0.9 s, 1.9 s, ..), else flies 1 m/s east;
    its estimate is the origin."""

    name = "flaky"

    def start(self, setup: Setup) -> int:
        return 0

    def step(self, state: int, inputs: Inputs) -> tuple[int, Output]:
        if round(inputs.now_s * 10) % 10 == 9:
            raise RuntimeError("every tenth step")
        return state + 1, Output(1 + 0j, 0j, 0j, {})


class Nan(Flaky):
    def step(self, state: int, inputs: Inputs) -> tuple[int, Output]:
        return state, Output(complex(math.nan, 0.0), 0j, 0j, {})


def test_a_failing_law_holds_its_vehicle_is_counted_and_the_run_goes_on() -> None:
    scenario = load_scenario("paper")
    run = simulate_law(scenario, Flaky(), 0.1, 5.0)
    cmd = run.series.command_m_s[:, :, 0]
    # Steps 9, 19, ... of each follower raised: their vehicles held for that step.
    assert run.law_failures == 4 * 5
    assert np.all(cmd[9::10] == 0.0) and np.all(cmd[:9] == 1.0)
    moved = run.series.follower_pos_m[-1, :, 0] - run.series.follower_pos_m[0, :, 0]
    assert np.allclose(moved, 0.1 * (50 - 5))
    nan = simulate_law(scenario, Nan(), 0.1, 1.0)
    assert nan.law_failures == 4 * 11 and np.all(nan.series.command_m_s == 0.0)
    assert np.all(np.isfinite(nan.series.follower_pos_m))


def test_the_estimator_runs_at_its_own_rate_between_control_steps() -> None:
    scenario = load_scenario("paper")
    law = make_law(lead_free(scenario))
    twice = simulate_law(scenario, law, 0.02, 4.0, estimator_dt_s=0.01)
    once = simulate_law(scenario, law, 0.02, 4.0)
    assert twice.series.estimate_m.shape == once.series.estimate_m.shape
    assert not np.array_equal(twice.series.estimate_m, once.series.estimate_m)
    assert np.abs(twice.series.estimate_m - once.series.estimate_m)[100:].max() < 0.05


def test_simulate_runs_the_papers_law_compiled_unless_asked_through_the_interface(
        tmp_path: Path) -> None:
    runs = {}
    for name, extra in (("compiled", []), ("interface", ["--through-interface"])):
        out = tmp_path / name
        assert main(["simulate", "paper", "--dt", "0.02", "--duration", "6", "--out", str(out),
                     "--no-progress", *extra]) == 0
        runs[name] = json.loads((out / "metrics.json").read_text())
    assert runs["compiled"]["law_path"] == "compiled" and "law_failures" not in runs["compiled"]
    assert runs["interface"]["law_path"] == "interface"
    assert runs["interface"]["law_failures"] == 0 and runs["interface"]["law"] == "paper"


class Scheduled(Flaky):
    """Raises on the control steps of 2.0 <= t_s < 2.5 (the run's time, not the clock)."""

    def step(self, state: int, inputs: Inputs) -> tuple[int, Output]:
        assert inputs.t_s == inputs.now_s  # lock-step's clock starts at the start
        if inputs.command and 2.0 <= inputs.t_s < 2.5:
            raise RuntimeError("scheduled")
        return state + 1, Output(1 + 0j, 0j, 0j, {})


def test_lock_step_runs_the_laws_time_from_zero() -> None:
    run = simulate_law(load_scenario("paper"), Scheduled(), 0.1, 4.0, estimator_dt_s=0.05)
    assert run.law_failures == 4 * 5
    held = np.all(run.series.command_m_s == 0.0, axis=(1, 2))
    assert list(run.series.t_s[held]) == pytest.approx([2.0, 2.1, 2.2, 2.3, 2.4])


def test_a_law_that_builds_inputs_as_before_still_can() -> None:
    setup = setup_for(load_scenario("paper"), 0)
    own = Sample(0j, 0j, 0.0)
    old = Inputs(5.0, 0.0, True, setup, own, {}, {}, None)  # today's eight, positionally
    assert (old.now_s, old.t_s, old.rebase_to) == (5.0, 0.0, None)
    assert old._replace(t_s=2.0)[-1] == 2.0 and len(old) == 9
