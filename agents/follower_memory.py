"""The networked follower's state, as the reference (agents.follower_logic) keeps it:
timestamped samples, what it keeps of a peer, its estimator memory and a tick's output.
Split from follower_logic, which re-exports every name."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
ZERO2 = np.zeros(2)


@dataclass(frozen=True)
class Sample:
    """A timestamped position (or estimate) with its rate, for first-order extrapolation."""

    value: FloatArray  # (2,)
    rate: FloatArray  # (2,)
    stamp_s: float

    def at(self, t_s: float) -> FloatArray:
        return self.value + self.rate * (t_s - self.stamp_s)

    def fresh(self, t_s: float, limit_s: float) -> bool:
        return t_s - self.stamp_s <= limit_s

    def held(self, t_s: float, limit_s: float) -> FloatArray:
        """The value at t_s, extrapolated over at most `limit_s` past its stamp, then held."""
        return self.at(min(t_s, self.stamp_s + limit_s))

    def held_rate(self, t_s: float, limit_s: float) -> FloatArray:
        return self.rate if self.fresh(t_s, limit_s) else ZERO2


@dataclass(frozen=True)
class TargetTrack(Sample):
    """A target's last observed position with its velocity (a Sample), and the filter state
    behind that velocity (agents.core.estimator_one.lag_free_velocity)."""

    smooth_m_s: FloatArray = field(default_factory=lambda: np.zeros(2))
    accel_m_s2: FloatArray = field(default_factory=lambda: np.zeros(2))
    primed: bool = False  # False until a second observation gave a velocity


@dataclass(frozen=True)
class PeerView:
    """Latest state a neighbour or the successor published."""

    r: Sample  # its estimate r_j and dr_j/dt
    pos: Sample  # its position and velocity
    flow: Sample | None = None  # robust: its running sum and rate on its link to us
    rv: Sample | None = None  # order 2: its estimate of the targets' mean velocity (held)
    vel_flow: Sample | None = None  # order 2: its velocity stage's sum and rate towards us


@dataclass(frozen=True)
class FollowerMemory:
    """Estimator state carried from tick to tick."""

    phi_m: FloatArray = field(default_factory=lambda: np.zeros(2))
    phi_rate_m_s: FloatArray = field(default_factory=lambda: np.zeros(2))
    last_tick_s: float | None = None
    # Per peer, the age of its data at use, low-passed: the step limits follow the typical
    # age, not each jittered sample (which would make the commands jump).
    peer_age_s: dict[int, float] = field(default_factory=dict)
    targets: dict[int, TargetTrack] = field(default_factory=dict)
    link_sums_m: FloatArray | None = None  # robust: (d, 2) own running sum per neighbour
    link_rates_m_s: FloatArray | None = None  # robust: (d, 2) the flows of the last tick
    # Continuity across membership changes (agents.estimate_carry): the last r_i we
    # computed, the carry added to it, and whether the next tick starts a new carry.
    last_r: Sample | None = None
    carry_m: FloatArray = field(default_factory=lambda: np.zeros(2))
    rebase_pending: bool = False
    # Order 2 (agents.scenario.model.Gains.estimator_order): the velocity stage's own running
    # sum and flow per neighbour (d, 2), and the estimate rv_i it published last.
    vel_sums_m_s: FloatArray | None = None
    vel_rates_m_s2: FloatArray | None = None
    rv_m_s: FloatArray = field(default_factory=lambda: np.zeros(2))


@dataclass(frozen=True)
class TickOutput:
    u_m_s: FloatArray
    r_m: FloatArray
    dr_m_s: FloatArray
    z_m: float
    delta: float
    stale: tuple[str, ...]  # inputs older than stale_after_s (or missing)
