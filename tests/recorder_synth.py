"""Synthetic recorder input: a perfect formation around moving targets, as bus messages.

Followers sit exactly on the pattern (radius rho_d, the scenario's included angles) around
the true LAP, and each estimate r_i is the LAP at its own stamp, with the LAP's velocity as
dr_i, so every error is ~0.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from agents.scenario.model import Scenario
from transport.key_exprs import SwarmKeys
from transport.messages import (
    FollowerState,
    Message,
    RunControl,
    Stamper,
    TruthSnapshot,
    vec2,
    vec3,
)

LAP_VEL_M_S = (0.5, 0.2)
SPIN_RAD_S = 0.1
ALTITUDE_M = 10.0


def lap_m(t_s: float) -> np.ndarray:
    return np.array([LAP_VEL_M_S[0] * t_s, LAP_VEL_M_S[1] * t_s])


def formation_m(scenario: Scenario, t_s: float) -> np.ndarray:
    """(n, 2) follower positions on the pattern around the LAP at experiment time t_s."""
    gaps = scenario.pattern.angles_rad
    theta = 0.3 + SPIN_RAD_S * t_s + np.concatenate([[0.0], np.cumsum(gaps[:-1])])
    # Walk the successor cycle so that follower i -> successor(i) spans angles_rad[i].
    order, i = [], 0
    for _ in range(scenario.n):
        order.append(i)
        i = scenario.successor[i]
    pos = np.empty((scenario.n, 2))
    for k, f in enumerate(order):
        pos[f] = lap_m(t_s) + scenario.pattern.rho_d_m * np.array(
            [math.cos(theta[k]), math.sin(theta[k])])
    return pos


def targets_m(scenario: Scenario, t_s: float) -> np.ndarray:
    """(m, 2) targets whose mean is the LAP."""
    offsets = np.array([[math.cos(a), math.sin(a)] for a in
                        np.linspace(0, 2 * math.pi, scenario.m, endpoint=False)])
    return lap_m(t_s) + offsets - offsets.mean(axis=0)


@dataclass
class SynthRun:
    """Messages of a short run, in sender-stamp order."""

    scenario: Scenario
    keys: SwarmKeys
    start_stamp_s: float
    duration_s: float = 2.0
    rate_hz: float = 50.0
    state_lag_s: float = 0.004  # follower state stamps trail the truth stamps by this
    pre_s: float = 0.2  # truth/states sent before the start (must be ignored)
    post_s: float = 0.2

    def truth(self, stamper: Stamper, t_s: float) -> TruthSnapshot:
        pos = formation_m(self.scenario, t_s)
        tgt = targets_m(self.scenario, t_s)
        zero3, zero2 = (0.0, 0.0, 0.0), (0.0, 0.0)
        return TruthSnapshot(
            stamper.header(self.start_stamp_s + t_s), t_s,
            tuple(vec3((p[0], p[1], ALTITUDE_M)) for p in pos), (zero3,) * self.scenario.n,
            tuple(vec2(p) for p in tgt), (zero2,) * self.scenario.m)

    def state(self, stamper: Stamper, i: int, t_s: float) -> FollowerState:
        pos = formation_m(self.scenario, t_s)[i]
        u = (0.1 * math.cos(t_s), 0.1 * math.sin(t_s))
        # Its law's fields (the robust estimator's link sums and rates towards its
        # successor), so the recorder's paths (MCAP JSON, read-back) carry them.
        succ = (i + 1) % self.scenario.n
        law = {"link_sums_m": ((succ, 0.01, -0.01),), "link_rates_m_s": ((succ, 0.0, 0.5),)}
        return FollowerState(stamper.header(self.start_stamp_s + t_s), i, vec2(lap_m(t_s)),
                             LAP_VEL_M_S, vec2(pos), LAP_VEL_M_S, u,
                             self.start_stamp_s + t_s, law)

    def control(self, stamper: Stamper, command: str) -> RunControl:
        return RunControl(stamper.header(), command, self.start_stamp_s, self.duration_s)

    def samples(self) -> Iterator[tuple[str, Message]]:
        """(key, message) of the run body: truth then states, per tick, no control."""
        truth_st = Stamper("sim-0")
        state_st = [Stamper(f"follower-{i}") for i in range(self.scenario.n)]
        dt = 1.0 / self.rate_hz
        steps = round((self.pre_s + self.duration_s + self.post_s) / dt)
        for k in range(steps + 1):
            t = -self.pre_s + k * dt
            yield self.keys.truth(), self.truth(truth_st, t)
            for i in range(self.scenario.n):
                yield self.keys.follower_state(i), self.state(state_st[i], i, t - self.state_lag_s)
