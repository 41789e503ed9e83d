"""Admissibility checks that need the whole scenario (graph, speeds, spread over time)."""

from __future__ import annotations

import math

from agents.scenario.model import Scenario, TargetSpec
from errors import InadmissibleError, ScenarioError

SPEED_TOL_M_S = 1e-9


def check_admissible(scenario: Scenario, whole_run: bool = True) -> None:
    """Raise `InadmissibleError` naming the field that breaks the paper's assumptions.

    `whole_run=False` leaves out the targets' spread over the run, which needs their
    whole trajectory (numpy): a follower process loads a scenario its launcher (or the
    user's `enclose` command) checked whole, and stays without numpy (issue 15)."""
    _check_connected(scenario)
    for j, spec in enumerate(scenario.targets):
        _check_speed(spec, j, scenario.beta_m_s)
    if whole_run:
        _check_spread(scenario)
    check_estimator_order(scenario, "gains.estimator_order")
    run = scenario.run
    if run.dt_s >= run.duration_s:
        raise ScenarioError("run.dt_s", f"must be shorter than run.duration_s ({run.duration_s})")
    if not 0.0 <= scenario.steady_from_s() < run.duration_s:
        raise ScenarioError("run.steady_from_s", "must lie within [0, run.duration_s)")


def check_estimator_order(scenario: Scenario, field: str) -> None:
    """The velocity stage lives in the robust estimator's link sums; `field` names the
    setting to blame (the scenario's, or a command-line override)."""
    if scenario.gains.estimator_order == 2 and scenario.network.estimator != "robust":
        raise ScenarioError(field, "2 needs the robust estimator (network.estimator = \"robust\")")


def _check_connected(scenario: Scenario) -> None:
    n = scenario.n
    seen, frontier = {0}, [0]
    while frontier:
        i = frontier.pop()
        for j in scenario.neighbours(i):
            if j not in seen:
                seen.add(j)
                frontier.append(j)
    if len(seen) != n:
        cut = sorted(set(range(n)) - seen)
        raise InadmissibleError(
            "graph.edges",
            f"follower graph is not connected: {[c + 1 for c in cut]} unreachable from 1",
        )


def _check_speed(spec: TargetSpec, j: int, beta: float) -> None:
    where = f"targets[{j}]"
    if spec.profile == "paper_v1":
        speed, key = 1.0, "profile"
    elif spec.profile == "paper_v2":
        speed, key = math.hypot(1.0, 0.5), "profile"
    elif spec.profile == "constant":
        speed, key = math.hypot(*spec.vel_m_s), "vel_m_s"
    elif spec.profile == "circle":
        rel = (spec.initial_pos_m[0] - spec.center_m[0], spec.initial_pos_m[1] - spec.center_m[1])
        speed, key = math.hypot(*rel) * abs(spec.omega_rad_s), "omega_rad_s"
    else:
        speed, key = spec.speed_max_m_s, "speed_max_m_s"
        if speed <= 0.0:
            raise ScenarioError(f"{where}.speed_max_m_s", "random_walk needs speed_max_m_s > 0")
    if speed > beta + SPEED_TOL_M_S:
        raise InadmissibleError(
            f"{where}.{key}", f"target speed {speed:.6g} m/s exceeds beta_m_s = {beta:.6g}"
        )


def _check_spread(scenario: Scenario) -> None:
    """rho_d must exceed every target's distance to the LAP over the whole run."""
    import numpy as np

    from agents.scenario.target_motion import TargetMotion

    times = np.linspace(0.0, scenario.run.duration_s, int(scenario.run.duration_s) + 2)
    pos, _ = TargetMotion(scenario).states(times)
    spread = np.linalg.norm(pos - pos.mean(axis=1, keepdims=True), axis=2).max()
    if scenario.pattern.rho_d_m <= spread:
        raise InadmissibleError(
            "pattern.rho_d_m",
            f"must exceed the targets' spread around their centre ({spread:.3f} m over the run)",
        )
