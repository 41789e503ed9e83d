"""The lock-step closed loop in plain numpy (tests/reference): the engine's oracle.

Followers p' = u by explicit Euler at dt; every follower's estimator on the graph at
once (reference.law.estimator_rates), `substeps` estimator steps per control step with
p~ moving linearly to its next sample; exact observations, their finite-difference rate.
"""

from __future__ import annotations

import numpy as np

from agents.analysis.timeseries import RunSeries
from agents.law.scenario_params import control_gains, estimator_params
from agents.lockstep.estimator_weights import observation_weights
from agents.scenario.model import Scenario
from agents.scenario.target_motion import TargetMotion
from tests.reference.law import Edges, enclosing_control, estimator_rates


def simulate(scenario: Scenario, dt_s: float, duration_s: float, substeps: int = 1) -> RunSeries:
    steps = round(duration_s / dt_s)
    t = np.arange(steps + 1, dtype=np.float64) * dt_s
    targets, _ = TargetMotion(scenario, horizon_s=duration_s).states(t)
    p_tilde = np.einsum("ij,kjd->kid", observation_weights(scenario.observation()), targets)
    p_rate = np.zeros_like(p_tilde)
    p_rate[1:] = np.diff(p_tilde, axis=0) / dt_s
    edges, params, gains = (Edges.of(scenario.adjacency()), estimator_params(scenario),
                            control_gains(scenario))
    succ, angles = np.asarray(scenario.successor), np.asarray(scenario.pattern.angles_rad)
    dt_e = dt_s / substeps
    pos, est, cmd = np.empty_like(p_tilde), np.empty_like(p_tilde), np.zeros_like(p_tilde)
    pos[0] = scenario.follower_pos_m
    phi, psi = np.zeros((scenario.n, 2)), np.zeros((scenario.n, 2))
    for k in range(steps + 1):
        r = phi + p_tilde[k]
        phi_rate, psi_rate = estimator_rates(r, psi, p_rate[k], edges, params, dt_e)
        out = enclosing_control(pos[k], pos[k][succ], r, phi_rate + p_rate[k], angles, gains,
                                dt_s)
        est[k], cmd[k] = r, out.u_m_s
        if k == steps:
            break
        pos[k + 1] = pos[k] + dt_s * out.u_m_s
        phi, psi = phi + dt_e * phi_rate, psi + dt_e * psi_rate
        for j in range(1, substeps):
            r = phi + p_tilde[k] + (j * dt_e) * p_rate[k + 1]
            phi_rate, psi_rate = estimator_rates(r, psi, p_rate[k + 1], edges, params, dt_e)
            phi, psi = phi + dt_e * phi_rate, psi + dt_e * psi_rate
    return RunSeries(t, pos, est, cmd, targets)
