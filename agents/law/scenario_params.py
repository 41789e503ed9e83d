"""Core parameter bundles derived from a scenario."""

from __future__ import annotations

from agents.law.consensus import EstimatorParams
from agents.law.enclosing import ControlGains
from agents.scenario.model import Scenario


def control_gains(scenario: Scenario) -> ControlGains:
    g, p = scenario.gains, scenario.pattern
    return ControlGains(g.k_z, g.alpha2, g.k_d, g.alpha3, p.rho_d_m, p.w_d_rad_s, g.step_fraction,
                        g.spacing_gain_age or 0.0)


def estimator_params(scenario: Scenario) -> EstimatorParams:
    g = scenario.gains
    return EstimatorParams(g.k_e, g.alpha1, g.est_step_fraction, g.estimator_order)
