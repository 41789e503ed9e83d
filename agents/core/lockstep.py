"""In-process lock-step integration of the paper's closed loop: no clock, no network.

Followers are single integrators p' = u (explicit Euler at dt).  Target positions
are sampled at every step; followers use only the targets they observe, and
estimate the targets' velocities by finite differences of those observations,
as the networked followers do.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from agents.core.controller import ControlGains, enclosing_control
from agents.core.estimator import (
    EdgeOperators,
    EstimatorParams,
    estimator_rate,
    observation_weights,
)
from agents.core.profiles import TargetMotion
from agents.core.timeseries import RunSeries
from agents.scenario import Scenario

ProgressFn = Callable[[float], None]


def control_gains(scenario: Scenario) -> ControlGains:
    g, p = scenario.gains, scenario.pattern
    return ControlGains(g.k_z, g.alpha2, g.k_d, g.alpha3, p.rho_d_m, p.w_d_rad_s, g.step_fraction)


def estimator_params(scenario: Scenario) -> EstimatorParams:
    g = scenario.gains
    return EstimatorParams(g.k_e, g.alpha1, g.step_fraction)


def simulate_lockstep(
    scenario: Scenario,
    dt_s: float,
    duration_s: float,
    progress: ProgressFn | None = None,
) -> RunSeries:
    """Integrate the closed loop for `duration_s` at step `dt_s`; every step is recorded."""
    steps = int(round(duration_s / dt_s))
    t = np.arange(steps + 1) * dt_s
    targets, _ = TargetMotion(scenario, horizon_s=duration_s).states(t)
    # Observations are exact here, so p~ and its finite-difference rate are precomputed.
    p_tilde = np.einsum("ij,kjd->kid", observation_weights(scenario.observation()), targets)
    p_tilde_rate = np.zeros_like(p_tilde)
    p_tilde_rate[1:] = np.diff(p_tilde, axis=0) / dt_s

    n = scenario.n
    edges = EdgeOperators.from_adjacency(scenario.adjacency())
    succ = np.asarray(scenario.successor)
    angles = np.asarray(scenario.pattern.angles_rad)
    gains = control_gains(scenario)
    params = estimator_params(scenario)

    pos = np.empty((steps + 1, n, 2))
    est = np.empty_like(pos)
    cmd = np.zeros_like(pos)
    pos[0] = np.asarray(scenario.follower_pos_m)
    phi = np.zeros((n, 2))
    report_every = max(1, steps // 100)
    for k in range(steps + 1):
        r = phi + p_tilde[k]
        phi_rate = estimator_rate(r, edges, params, dt_s)
        p = pos[k]
        out = enclosing_control(p, p[succ], r, phi_rate + p_tilde_rate[k], angles, gains, dt_s)
        est[k] = r
        cmd[k] = out.u_m_s
        if k < steps:
            pos[k + 1] = p + dt_s * out.u_m_s
            phi = phi + dt_s * phi_rate
        if progress is not None and k % report_every == 0:
            progress(k / steps)
    return RunSeries(t, pos, est, cmd, targets)
