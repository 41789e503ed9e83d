"""The LAP estimator's consensus (paper, eq. smoothingEstimator), one link at a time.

    r_i = Phi_i + p~_i,   dPhi_i/dt = k_e * sum_j a_ij sig(r_j - r_i)^(1/alpha1)

with p~_i = (n/m) * sum_{j in N_i^T} p_j^t / |N_j^F|.  Each link's flow is odd in
r_j - r_i, so a link's two flows cancel and mean(r) stays the LAP.  Nothing here knows
about clocks or networks: time steps and neighbour values are arguments.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from agents.law.sig import limited_sig


@dataclass(frozen=True)
class EstimatorParams:
    """k_e and alpha1 of the paper; `step_fraction` caps one step's flow (0: plain Euler);
    `order` 2 adds the velocity stage (agents.scenario.model.Gains.estimator_order)."""

    k_e: float
    alpha1: float
    step_fraction: float = 0.5
    order: int = 1


def link_flow(r_self_m: complex, r_nbr_m: complex, k_e: float, inv_alpha1: float,
              rate_cap_per_s: float) -> complex:
    """One link's share of dPhi_i/dt: k_e sig(r_j - r_i)^(1/alpha1), step-limited per
    component (`rate_cap_per_s`: the step's cap times the link's edge fraction)."""
    gap = r_nbr_m - r_self_m
    return complex(limited_sig(gap.real, inv_alpha1, k_e, rate_cap_per_s),
                   limited_sig(gap.imag, inv_alpha1, k_e, rate_cap_per_s))


def link_balance(own_sums_m: Sequence[complex], their_sums_m: Sequence[complex]) -> complex:
    """Phi of the robust estimator: half the difference of each link's two running sums.

    Follower i integrates its own flow on link j into S_ij; j does the same into S_ji and
    publishes it.  Phi_i = sum_j (S_ij - S_ji) / 2 makes every link's contributions to
    Phi_i and Phi_j exact opposites, whatever was lost or late, so sum(Phi) = 0 (mean r =
    LAP) holds up to the sums still in flight; with the paper's increments a lost or late
    message shifts the mean for good.
    """
    total = 0j
    for own, theirs in zip(own_sums_m, their_sums_m):  # noqa: B905 (numba: no strict)
        total += own - theirs
    return 0.5 * total
