"""Target motion profiles as pure functions of time.

Every profile gives position and velocity in closed form at any time, so the
lock-step simulator, the target processes and the recorder agree exactly on
where a target is.  Time before `start_s` holds the target at its start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agents.scenario.model import Scenario, TargetSpec

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RandomWalkKnots:
    """Velocity knots of a seeded bounded random walk, linearly interpolated in time."""

    interval_s: float
    vel_m_s: FloatArray  # (k, 2), every row of norm <= speed_max
    pos_m: FloatArray  # (k, 2), position at each knot


def random_walk_knots(spec: TargetSpec, horizon_s: float) -> RandomWalkKnots:
    """Knots for `spec` up to `horizon_s`; a convex mix of knots keeps |v| <= speed_max."""
    rng = np.random.default_rng(spec.seed)
    count = math.ceil(horizon_s / spec.knot_interval_s) + 2
    vmax = spec.speed_max_m_s
    vel = np.zeros((count, 2))
    for k in range(1, count):
        step = vel[k - 1] + rng.normal(0.0, 0.5 * vmax, size=2)
        norm = float(np.hypot(*step))
        vel[k] = step if norm <= vmax else step * (vmax / norm)
    seg = 0.5 * (vel[1:] + vel[:-1]) * spec.knot_interval_s
    pos = np.vstack([np.zeros((1, 2)), np.cumsum(seg, axis=0)]) + np.asarray(spec.initial_pos_m)
    return RandomWalkKnots(spec.knot_interval_s, vel, pos)


def _random_walk(knots: RandomWalkKnots, t_s: FloatArray) -> tuple[FloatArray, FloatArray]:
    k = np.minimum((t_s // knots.interval_s).astype(int), len(knots.vel_m_s) - 2)
    tau = (t_s - k * knots.interval_s)[:, None]
    v0, v1 = knots.vel_m_s[k], knots.vel_m_s[k + 1]
    slope = (v1 - v0) / knots.interval_s
    return knots.pos_m[k] + v0 * tau + 0.5 * slope * tau * tau, v0 + slope * tau


def _closed_form(spec: TargetSpec, t_s: FloatArray) -> tuple[FloatArray, FloatArray]:
    p0 = np.asarray(spec.initial_pos_m, dtype=np.float64)
    one, zero = np.ones_like(t_s), np.zeros_like(t_s)
    if spec.profile == "paper_v1":
        return p0 + np.stack([t_s, zero], axis=1), np.stack([one, zero], axis=1)
    if spec.profile == "paper_v2":
        phase = t_s / 10.0 + math.pi / 4.0
        dy = 5.0 * (math.cos(math.pi / 4.0) - np.cos(phase))
        return p0 + np.stack([t_s, dy], axis=1), np.stack([one, 0.5 * np.sin(phase)], axis=1)
    if spec.profile == "constant":
        vel = np.asarray(spec.vel_m_s, dtype=np.float64)
        return p0 + vel * t_s[:, None], np.broadcast_to(vel, (len(t_s), 2)).copy()
    # circle: radius and start angle come from the start position around the centre
    center = np.asarray(spec.center_m, dtype=np.float64)
    rel = p0 - center
    radius, angle0 = float(np.hypot(*rel)), math.atan2(rel[1], rel[0])
    angle = angle0 + spec.omega_rad_s * t_s
    pos = center + radius * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    vel = radius * spec.omega_rad_s * np.stack([-np.sin(angle), np.cos(angle)], axis=1)
    return pos, vel


class TargetMotion:
    """Positions and velocities of all targets of a scenario at any time."""

    def __init__(self, scenario: Scenario, horizon_s: float | None = None) -> None:
        horizon = scenario.run.duration_s if horizon_s is None else horizon_s
        self._specs = scenario.targets
        self._start_s = scenario.run.target_start_s
        self._knots = {
            j: random_walk_knots(spec, horizon + 1.0)
            for j, spec in enumerate(self._specs)
            if spec.profile == "random_walk"
        }

    def state(self, t_s: float) -> tuple[FloatArray, FloatArray]:
        """(m, 2) positions and (m, 2) velocities at time `t_s`."""
        pos, vel = self.states(np.array([t_s]))
        return pos[0], vel[0]

    def state_of(self, j: int, t_s: float) -> tuple[FloatArray, FloatArray]:
        """Target j's (2,) position and velocity at time `t_s` (a target process flies its
        own alone: the others' would double its work at every tick)."""
        pos, vel = self._one(j, np.array([max(0.0, t_s - self._start_s)]))
        return pos[0], (vel[0] if t_s >= self._start_s else np.zeros(2))

    def states(self, times_s: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(k, m, 2) positions and velocities at each of `times_s`, vectorised over time."""
        t = np.asarray(times_s, dtype=np.float64)
        tau = np.maximum(0.0, t - self._start_s)
        pos = np.empty((len(t), len(self._specs), 2))
        vel = np.empty_like(pos)
        for j in range(len(self._specs)):
            pos[:, j], vel[:, j] = self._one(j, tau)
        vel[t < self._start_s] = 0.0
        return pos, vel

    def _one(self, j: int, tau: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(k, 2) positions and velocities of target j at times `tau` since the start."""
        if j in self._knots:
            return _random_walk(self._knots[j], tau)
        return _closed_form(self._specs[j], tau)
