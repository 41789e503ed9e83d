"""What a vehicle reports of its own position: the truth plus white noise and a slow,
seeded random-walk bias, as a GPS receiver's fix wanders (`[vehicle] gps_noise_std_m`,
`gps_bias_walk_m_s`).  Horizontal only: an autopilot holds altitude on its barometer."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from agents.scenario.model import VehicleConfig

FloatArray = NDArray[np.float64]


class GpsNoise:
    """The (n, 2) error each of `n` vehicles' reported position carries, advanced per step."""

    def __init__(self, vehicle: VehicleConfig, n: int) -> None:
        self.std_m = vehicle.gps_noise_std_m
        self.walk_m_s = vehicle.gps_bias_walk_m_s
        self.rng = np.random.default_rng(vehicle.gps_seed)
        self.bias = np.zeros((n, 2))
        self.error = np.zeros((n, 2))

    def advance(self, dt_s: float) -> FloatArray:
        """The error after one more step of `dt_s` (a fresh white draw on the walked bias)."""
        draws = self.rng.standard_normal((2, *self.bias.shape))
        self.bias = self.bias + (self.walk_m_s * math.sqrt(dt_s)) * draws[0]
        self.error = self.bias + self.std_m * draws[1]
        return self.error
