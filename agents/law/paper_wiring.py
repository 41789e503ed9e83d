"""How the paper's law wires its equations to its gains, written once.

The follower's law (agents.law.paper, one follower, complex scalars) and the lock-step
kernel (agents.lockstep.kernel, the whole swarm, compiled by numba) both call these: a
link's consensus flow and a follower's command are one call each here, on one vector of
the law's gains, so that neither can pass the other's gains in another order or form.
Plain functions of numbers (numba compiles them into the kernel); `gains` is a tuple for
the law, a float64 array in the kernel.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from agents.law.consensus import EstimatorParams, link_flow
from agents.law.enclosing import ControlGains, enclosing_control
from agents.law.sig import rate_cap

# Where each gain sits in the vector `gains_of` makes and the wiring reads.  The alphas
# are held as their inverses, the powers the equations take (1/alpha, divided once).
K_E, INV_ALPHA1, EST_CAP, ORDER, K_Z, INV_ALPHA2, K_D, INV_ALPHA3, RHO_D, W_D, STEP_FRACTION, \
    SPACING_GAIN_AGE = range(12)
# The flows run per link and step in every follower: they index by number, not by a
# global name (a lookup each); these are those numbers.
if (K_E, INV_ALPHA1, EST_CAP) != (0, 1, 2):
    raise AssertionError("estimator_flow(s) read gains[0], [1], [2]")


class Gains(Protocol):
    """A tuple of floats for the law, a float64 array in the kernel."""

    def __getitem__(self, index: int, /) -> float: ...


def gains_of(estimator: EstimatorParams, control: ControlGains,
             est_period_s: float) -> tuple[float, ...]:
    """The law's gains as one vector (the estimator's step cap for steps of `est_period_s`)."""
    c = control
    return (estimator.k_e, 1.0 / estimator.alpha1,
            rate_cap(estimator.step_fraction, est_period_s), float(estimator.order), c.k_z,
            1.0 / c.alpha2, c.k_d, 1.0 / c.alpha3, c.rho_d_m, c.w_d_rad_s, c.step_fraction,
            c.spacing_gain_age)


def second_order(gains: Gains) -> bool:
    """Whether the estimator has the velocity stage (agents.law.velocity_stage)."""
    return gains[ORDER] > 1.5


def estimator_flow(r_self_m: complex, r_nbr_m: complex, gains: Gains,
                   fraction: float) -> complex:
    """A link's consensus flow: link_flow with k_e, 1/alpha1 and the step cap scaled by
    the link's (edge) fraction."""
    return link_flow(r_self_m, r_nbr_m, gains[0], gains[1], gains[2] * fraction)


def estimator_flows(r_self_m: complex, r_nbrs_m: Sequence[complex],
                    fractions: Sequence[float], gains: Gains) -> list[complex]:
    """`estimator_flow` on each of one follower's links, its gains read once: the
    follower's law, where a call per link would be a tenth of its step
    (tests/unit/test_paper_wiring.py pins the two equal)."""
    k_e, inv_alpha1, cap = gains[0], gains[1], gains[2]
    flows = []  # a loop, not a comprehension: one frame less (Python 3.11)
    for r_j, f in zip(r_nbrs_m, fractions, strict=False):
        flows.append(link_flow(r_self_m, r_j, k_e, inv_alpha1, cap * f))
    return flows


def command(own_m: complex, succ_m: complex, r_m: complex, dr_m_s: complex, angle_rad: float,
            gains: Gains, period_s: float, succ_age_s: float) -> complex:
    """The enclosing controller's velocity command u_i."""
    u, _, _ = enclosing_control(own_m, succ_m, r_m, dr_m_s, angle_rad, gains[K_Z],
                                gains[INV_ALPHA2], gains[K_D], gains[INV_ALPHA3],
                                gains[RHO_D], gains[W_D], gains[STEP_FRACTION],
                                gains[SPACING_GAIN_AGE], period_s, succ_age_s)
    return u
