"""What one follower knows of the scenario, fixed for a run (or until the members change).

Numpy-free: the follower process builds it at every membership change and must not
import numpy (issue 15: <= 50 MB per follower); agents.follower_logic, the numpy
reference, makes arrays of its weights and edge fractions where it computes, and
tests/unit/test_follower_setup.py pins them to the reference's matrices
(agents.core.estimator.edge_fractions, Membership.weights).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from agents.core.controller_one import ControlGains
from agents.core.estimator_one import EstimatorParams
from agents.core.params import control_gains, estimator_params
from agents.membership import membership
from agents.scenario.model import Scenario


@dataclass(frozen=True)
class FollowerSetup:
    """What follower `index` knows of the scenario, fixed for a run."""

    index: int
    weights: tuple[float, ...]  # (m,) its row of W: p~_i = weights @ target positions
    observed: tuple[int, ...]  # targets with a non-zero weight
    neighbours: tuple[int, ...]
    nbr_fractions: tuple[float, ...]  # (d,) edge fractions, aligned with neighbours
    successor: int
    angle_rad: float
    estimator: EstimatorParams
    control: ControlGains
    period_s: float
    robust: bool = False  # the link-sum estimator (agents.core.estimator.link_balance)
    stale_after_s: float = 0.5  # a peer older than this is missing (no flow, no spacing)
    hold_after_s: float = 1.0  # longest extrapolation of any input; held afterwards
    target_vel_tau_s: float = 0.1
    target_accel_tau_s: float = 0.5  # the acceleration that undoes the velocity's lag
    lead_s: float = 0.0  # the law runs on the state predicted this far ahead (Gains.lead_s)
    max_gap_s: float = 0.25  # longest dt the estimator integrates over one tick
    age_tau_s: float = 0.5  # time constant of the low-passed data ages
    # The estimator's own step (issue 15): it advances between control ticks too, on
    # what its neighbours published at that rate; None: one step per control tick.
    estimator_period_s: float | None = None

    @property
    def est_period_s(self) -> float:
        return self.period_s if self.estimator_period_s is None else self.estimator_period_s

    @staticmethod
    def from_scenario(
        scenario: Scenario, index: int, members: Iterable[int] | None = None
    ) -> FollowerSetup:
        """Follower `index`'s share of the swarm formed by `members` (default: everyone)."""
        form = membership(scenario, range(scenario.n) if members is None else members)
        weights = form.weight_row(index)
        nbrs = form.neighbours(index)
        return FollowerSetup(
            index=index,
            weights=weights,
            observed=tuple(j for j, w in enumerate(weights) if w != 0.0),
            neighbours=nbrs,
            nbr_fractions=tuple(form.edge_fraction(index, j) for j in nbrs),
            successor=form.successor[index],
            angle_rad=form.angles_rad[index],
            estimator=estimator_params(scenario),
            control=control_gains(scenario),
            period_s=1.0 / scenario.run.rate_hz,
            estimator_period_s=1.0 / scenario.run.estimator_hz,
            robust=scenario.network.estimator == "robust",
            lead_s=scenario.gains.lead_s,
        )
