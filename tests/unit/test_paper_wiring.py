"""The paper's law wired once (agents.law.paper_wiring): the gains vector the follower's
law and the lock-step kernel both read, and its two calls against the equations."""

from __future__ import annotations

import numpy as np

from agents.law import paper_wiring as w
from agents.law.consensus import EstimatorParams, link_flow
from agents.law.enclosing import ControlGains, enclosing_control
from agents.law.sig import rate_cap
from agents.lockstep.kernel import law_vector

EST = EstimatorParams(k_e=1.5, alpha1=2.0, step_fraction=0.25, order=2)
CTRL = ControlGains(k_z=0.8, alpha2=3.0, k_d=0.6, alpha3=5.0, rho_d_m=7.0, w_d_rad_s=0.3,
                    step_fraction=0.4, spacing_gain_age=0.05)


def test_each_gain_is_read_where_it_is_written() -> None:
    g = w.gains_of(EST, CTRL, 0.01)
    assert (g[w.K_E], g[w.INV_ALPHA1], g[w.EST_CAP], g[w.ORDER]) == (
        1.5, 1 / 2.0, rate_cap(0.25, 0.01), 2.0)
    assert (g[w.K_Z], g[w.INV_ALPHA2], g[w.K_D], g[w.INV_ALPHA3], g[w.RHO_D], g[w.W_D],
            g[w.STEP_FRACTION], g[w.SPACING_GAIN_AGE]) == (0.8, 1 / 3.0, 0.6, 1 / 5.0, 7.0, 0.3,
                                                           0.4, 0.05)
    assert w.second_order(g)
    # The kernel's float array holds the same numbers, bit for bit.
    assert law_vector(EST, CTRL, 0.01).tobytes() == np.array(g, np.float64).tobytes()


def test_the_wiring_is_the_equations_with_these_gains() -> None:
    g = w.gains_of(EST, CTRL, 0.01)
    assert w.estimator_flow(1 + 2j, -3 + 0.5j, g, 0.5) == link_flow(
        1 + 2j, -3 + 0.5j, 1.5, 0.5, rate_cap(0.25, 0.01) * 0.5)
    u, _, _ = enclosing_control(1 + 1j, 4 - 2j, 0.5j, 0.1 + 0.2j, 1.2, 0.8, 1 / 3.0, 0.6,
                                1 / 5.0, 7.0, 0.3, 0.4, 0.05, 0.02, 0.1)
    assert w.command(1 + 1j, 4 - 2j, 0.5j, 0.1 + 0.2j, 1.2, g, 0.02, 0.1) == u


def test_a_followers_flows_are_its_links_flows() -> None:
    g = w.gains_of(EST, CTRL, 0.02)
    nbrs, fractions = [3 - 1j, -2 + 0.25j, 0.5j], [0.5, 0.25, 1.0]
    assert w.estimator_flows(1 + 2j, nbrs, fractions, g) == [
        w.estimator_flow(1 + 2j, r_j, g, f) for r_j, f in zip(nbrs, fractions, strict=True)]
