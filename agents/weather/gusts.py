"""The wind: a mean plus first-order (Ornstein-Uhlenbeck, Dryden-like) gusts, seeded.

`gust_step` is the one place the gust process is written; the networked simulator
(sim_backend.runtime) and lock-step (agents.lockstep.engine) both advance a `WindField`,
so the same scenario and seed give both the same gusts at the same step size.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from agents.scenario.weather_tables import WindConfig

FloatArray = NDArray[np.float64]


def gust_step(state: FloatArray, dt_s: float, std_m_s: float, tau_s: float,
              draw: FloatArray) -> FloatArray:
    """The gusts `dt_s` later: the exact discretisation of dx = -x/tau dt + sigma sqrt(2/tau) dW,
    so the stationary standard deviation is `std_m_s` at any step (`draw`: standard normals,
    the shape of `state`)."""
    decay = math.exp(-dt_s / tau_s)
    return state * decay + (std_m_s * math.sqrt(1.0 - decay * decay)) * draw


class WindField:
    """The wind each of `n` vehicles feels, advanced one step at a time (ENU, m/s)."""

    def __init__(self, wind: WindConfig, n: int) -> None:
        self.wind = wind
        self.rng = np.random.default_rng(wind.seed)
        rows = n if wind.per_vehicle else 1
        self.n = n
        # Started in the stationary distribution: a run does not begin in calm air.
        self.gust = wind.gust_std_m_s * self.rng.standard_normal((rows, 2))
        self.mean = np.asarray(wind.mean_m_s, np.float64)
        self.std_m_s = wind.gust_std_m_s  # a timeline window may change it (agents.weather)

    def velocity(self) -> FloatArray:
        """(n, 2) wind velocity now."""
        return np.broadcast_to(self.mean + self.gust, (self.n, 2)).copy()

    def advance(self, dt_s: float) -> FloatArray:
        """The wind after one more step of `dt_s`, (n, 2)."""
        draw = self.rng.standard_normal(self.gust.shape)
        self.gust = gust_step(self.gust, dt_s, self.std_m_s, self.wind.gust_tau_s, draw)
        return self.velocity()


def steady_leak(drag_1_s: float, tau_s: float, dt_s: float | None = None) -> float:
    """The share of the wind a first-order velocity loop of lag `tau_s` lets through at
    steady state against the wind's push `drag_1_s` x wind: what lock-step's single
    integrators feel (None: in continuous time, drag x tau; `dt_s`: the simulator's discrete
    step, sim_backend.kinematics, which at 50 Hz lets a fifth less through)."""
    if dt_s is None:
        return drag_1_s * tau_s
    kept = math.exp(-dt_s / tau_s)
    return (1.0 - math.exp(-dt_s * drag_1_s)) * kept / (1.0 - kept)


def wind_ned(wind_enu: FloatArray) -> FloatArray:
    """(n, 2) ENU wind as (n, 3) NED, horizontal."""
    out = np.zeros((wind_enu.shape[0], 3))
    out[:, 0] = wind_enu[:, 1]
    out[:, 1] = wind_enu[:, 0]
    return out
