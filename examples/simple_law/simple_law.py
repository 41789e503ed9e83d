"""A simpler enclosing law than the paper's, written only against enclose's law interface.

Estimator: plain average consensus.  Follower i estimates the targets' centre as
    r_i = p~_i + phi_i,    dphi_i/dt = k_c * sum over neighbours j of (r_j - r_i),
p~_i being its weighted observation of the targets (the platform's `reference`).  On a
connected graph with symmetric links the phi_i sum to zero, so the mean of the r_i is the
mean of the p~_i: the targets' centre.  Unlike the paper's finite-time estimator it tracks
moving targets with a small standing error, about (spread of dp~/dt) / (k_c * lambda_2).

Controller: proportional.  Around its estimate r_i, follower i corrects its radius and its
angle to its successor, and circles at the desired rate:
    u_i = dr_i/dt - k_r (rho_i - rho_d) e_i + rho_i (w_d + k_s (gap_i - a_i)) (i e_i),
e_i the unit vector from r_i to the vehicle, gap_i the counter-clockwise angle to the
successor, a_i the desired one; |u_i| is capped at max_speed_m_s.

Plane vectors are complex numbers x + iy, as the interface gives them.  Plain Python, no
numpy: a follower process runs one step per control tick in well under a millisecond.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Mapping
from typing import Any, NamedTuple

from agents.law.interface import Inputs, Law, Output, ScenarioError, Setup, reference

# The law's parameters ([law] table keys) and their defaults.
DEFAULTS = {"k_c": 5.0, "k_r": 1.0, "k_s": 1.0, "max_speed_m_s": 10.0}
# After a change of members the estimate continues from the platform's `rebase_to` and
# the jump this hides decays with this time constant.
CARRY_TAU_S = 3.0


class SimpleState(NamedTuple):
    phi_m: complex = 0j  # the consensus correction: r_i = p~_i + phi_i + carry_m
    carry_m: complex = 0j  # what keeps r_i continuous across a change of members


class SimpleLaw(Law[SimpleState]):
    """Average consensus on the targets' centre and a proportional circle-and-spacing law."""

    name = "simple"

    def __init__(self, k_c: float, k_r: float, k_s: float, max_speed_m_s: float) -> None:
        self.k_c, self.k_r, self.k_s, self.max_speed_m_s = k_c, k_r, k_s, max_speed_m_s

    @classmethod
    def from_params(cls, table: Mapping[str, object], scenario: Any) -> SimpleLaw:
        values = dict(DEFAULTS)
        for key, raw in table.items():
            if key not in DEFAULTS:
                raise ScenarioError(f"law.{key}", f"unknown parameter (known: "
                                    f"{', '.join(DEFAULTS)})")
            if isinstance(raw, bool) or not isinstance(raw, int | float) \
                    or not math.isfinite(raw) or raw <= 0:
                raise ScenarioError(f"law.{key}", f"must be a positive number, got {raw!r}")
            values[key] = float(raw)
        return cls(**values)

    def start(self, setup: Setup) -> SimpleState:
        return SimpleState()

    def step(self, state: SimpleState, inputs: Inputs) -> tuple[SimpleState, Output]:
        setup, now, dt = inputs.setup, inputs.now_s, inputs.dt_s
        p, p_rate = reference(setup, inputs.targets, now)
        carry = state.carry_m * math.exp(-dt / CARRY_TAU_S)
        if inputs.rebase_to is not None:
            carry = inputs.rebase_to - (p + state.phi_m)
        r = p + state.phi_m + carry
        flow = 0j
        for j in setup.neighbours:
            peer = inputs.peers[j].r
            if now - peer.stamp_s <= setup.stale_s:  # a silent neighbour carries no flow
                flow += self.k_c * (peer.held(now, setup.hold_s) - r)
        dr = p_rate + flow - carry / CARRY_TAU_S
        u = self._command(inputs, r, dr) if inputs.command else 0j
        return SimpleState(state.phi_m + dt * flow, carry), Output(u, r, dr, {})

    def _command(self, inputs: Inputs, r: complex, dr: complex) -> complex:
        setup, now = inputs.setup, inputs.now_s
        rel = inputs.own.held(now, setup.hold_s) - r
        rho = max(abs(rel), 1e-6)
        unit = rel / rho
        turn = setup.w_d_rad_s
        succ = inputs.peers.get(setup.successor)
        if setup.successor != setup.index and succ is not None \
                and now - succ.pos.stamp_s <= setup.stale_s:
            ahead = succ.pos.held(now, setup.hold_s) - r
            a = setup.angle_rad
            gap = (cmath.phase(ahead * rel.conjugate()) - a + math.pi) % (2 * math.pi) \
                - math.pi + a
            turn += self.k_s * (gap - a)
        u = dr - self.k_r * (rho - setup.rho_d_m) * unit + rho * turn * 1j * unit
        speed = abs(u)
        return u if speed <= self.max_speed_m_s else u * (self.max_speed_m_s / speed)
