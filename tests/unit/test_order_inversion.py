"""A successor fallen behind is waited for, not chased round the ring (issue 10).

A follower killed and restarted leaves its vehicle holding still while the ring turns on,
so when it is back its neighbours have passed it.  With the paper's gap in [0, 2 pi) its
predecessor then reads a gap of almost a whole turn and races round the ring: the ring
winds up (every gap a few slots wide) and stays wound.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from agents.analysis.metrics import compute_metrics, error_series
from agents.law.enclosing import ControlGains, enclosing_control
from agents.loading.scenario_file import load_scenario
from agents.lockstep.engine import simulate_lockstep
from tests.reference.law import enclosing_control as reference_control

GAINS = ControlGains(2.0, 3.0, 2.0, 3.0, 8.0, 0.2, 0.25)


def _delta(succ_bearing_rad: float, angle_rad: float) -> tuple[float, float]:
    pos, succ = complex(8.0, 0.0), 8.0 * complex(math.cos(succ_bearing_rad),
                                                   math.sin(succ_bearing_rad))
    g = GAINS
    _, _, one = enclosing_control(pos, succ, 0j, 0j, angle_rad, g.k_z, 1.0 / g.alpha2, g.k_d,
                                  1.0 / g.alpha3, g.rho_d_m, g.w_d_rad_s, g.step_fraction,
                                  g.spacing_gain_age, 0.02, 0.0)
    out = reference_control(np.array([[8.0, 0.0]]), np.array([[succ.real, succ.imag]]),
                            np.zeros((1, 2)), np.zeros((1, 2)), np.array([angle_rad]), GAINS,
                            0.02)
    return one, float(out.delta[0])


@pytest.mark.timeout(30)
def test_a_successor_just_behind_reads_as_a_negative_gap() -> None:
    a = math.radians(22.5)
    for bearing, expected in ((a, 0.0), (2 * a, 1.0), (-0.1, -1.0 - 0.1 / a),
                              (-2 * a, -3.0), (math.pi + a - 0.01, (math.pi - 0.01) / a)):
        one, vec = _delta(bearing, a)
        assert one == pytest.approx(expected, abs=1e-9) and vec == pytest.approx(one, abs=1e-12)


@pytest.mark.timeout(60)
def test_a_ring_with_inverted_followers_unwinds() -> None:
    ring = load_scenario("ring16")
    pos = list(ring.follower_pos_m)
    pos[4], pos[5] = pos[5], pos[4]  # follower 5 one slot behind its place
    pos[8], pos[9], pos[10] = pos[9], pos[10], pos[8]  # follower 10 two slots behind
    inverted = dataclasses.replace(ring, follower_pos_m=tuple(pos))
    series = simulate_lockstep(inverted, 0.02, 60.0)
    angles = np.asarray(ring.pattern.angles_rad)
    errors = error_series(series, ring.successor, angles, ring.pattern.rho_d_m)
    metrics = compute_metrics(series, errors, 40.0, 0.0999, 0.0199)
    assert metrics.angle_error < 0.0199  # wound, as before: 3.09
    assert metrics.radius_error_m < 0.0999
