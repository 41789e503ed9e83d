"""Closed-loop properties of the lock-step simulator at coarse steps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.analysis.metrics import compute_metrics, error_series, settle_time
from agents.loading.scenario_file import load_scenario, parse_scenario, shipped_text
from agents.lockstep.engine import simulate_lockstep


def metrics_of(scenario, dt_s: float, duration_s: float):  # type: ignore[no-untyped-def]
    series = simulate_lockstep(scenario, dt_s, duration_s)
    angles = np.asarray(scenario.pattern.angles_rad)
    errors = error_series(series, scenario.successor, angles, scenario.pattern.rho_d_m)
    return series, compute_metrics(series, errors, duration_s / 2, 0.0999, 0.0199)


@pytest.mark.timeout(60)
def test_paper_case_converges_at_a_coarse_step() -> None:
    series, m = metrics_of(load_scenario(), 0.02, 60.0)
    assert m.estimator_error_m < 0.0999
    assert m.radius_error_m < 0.0999
    assert m.angle_error < 0.0199
    assert m.settle_time_s is not None and m.settle_time_s < 15.0
    assert m.command_jump_m_s < 0.5
    # The estimates' mean is the LAP at every step: the conservation the estimator rests on.
    np.testing.assert_allclose(series.estimate_m.mean(axis=1), series.lap_m, atol=1e-9)


@pytest.mark.timeout(60)
def test_plain_euler_dithers_where_the_step_limited_law_does_not() -> None:
    text = load_scenario_text().replace("alpha3 = 3.0", "alpha3 = 3.0\nstep_fraction = 0.0")
    _, plain = metrics_of(parse_scenario(text), 0.02, 40.0)
    _, limited = metrics_of(load_scenario(), 0.02, 40.0)
    assert plain.command_jump_m_s > 10 * limited.command_jump_m_s


def load_scenario_text() -> str:
    return shipped_text("paper")


SIX = """
name = "six"
beta_m_s = 0.6
[run]
duration_s = 60.0
[pattern]
rho_d_m = 16.0
w_d_rad_s = 0.3
[graph]
edges = [[1, 2], [2, 3], [3, 4], [4, 5], [5, 6], [6, 1], [1, 4]]
[[followers]]
pos_m = [30.0, 0.0]
[[followers]]
pos_m = [0.0, 25.0]
[[followers]]
pos_m = [-20.0, 20.0]
[[followers]]
pos_m = [-25.0, -5.0]
[[followers]]
pos_m = [-5.0, -30.0]
[[followers]]
pos_m = [20.0, -20.0]
[[targets]]
pos_m = [0.0, 0.0]
profile = "circle"
center_m = [-2.0, 0.0]
omega_rad_s = 0.2
observed_by = [1]
[[targets]]
pos_m = [1.0, 2.0]
profile = "constant"
vel_m_s = [0.3, -0.2]
observed_by = [2, 5]
[[targets]]
pos_m = [-1.0, 1.0]
profile = "random_walk"
speed_max_m_s = 0.5
seed = 11
observed_by = [4]
"""


@pytest.mark.timeout(60)
def test_any_connected_graph_and_observation_map_converges() -> None:
    s = parse_scenario(SIX)
    assert s.n == 6 and s.m == 3
    _, m = metrics_of(s, 0.02, 60.0)
    assert m.estimator_error_m < 0.0999
    assert m.radius_error_m < 0.0999
    assert m.angle_error < 0.0199
    assert math.isfinite(m.command_jump_m_s) and m.command_jump_m_s < 0.5


def test_settle_time_is_the_last_entry_into_the_band() -> None:
    t = np.arange(6.0)
    assert settle_time(t, np.array([False, True, False, True, True, True])) == 3.0
    assert settle_time(t, np.ones(6, dtype=bool)) == 0.0
    assert settle_time(t, np.array([True, True, True, True, True, False])) is None
