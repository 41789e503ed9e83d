"""A limited target sensor (`[sensing]`): range, detection probability, noise and latency.

A target out of range or missed is not observed that step (the follower's hold and stale
limits then apply, as to a lost message); the sensor counts both.  With `range_bearing`
the sensor measures range and bearing from the observer's true position and places the
target from the observer's own reported (noisy GPS) position, as an on-board sensor does.
"""

from __future__ import annotations

import math
from collections import Counter, deque

import numpy as np
from numpy.typing import NDArray

from agents.scenario.weather_tables import SensingConfig

FloatArray = NDArray[np.float64]


class TargetSensor:
    """Every observer's sensor; `observe` is called once per observation, in a fixed order."""

    def __init__(self, cfg: SensingConfig) -> None:
        self.cfg = cfg
        self.rng = np.random.default_rng(cfg.seed)
        self.counters: Counter[str] = Counter()
        self._past: deque[tuple[float, FloatArray, FloatArray]] = deque()

    def remember(self, t_s: float, pos_enu: FloatArray, reported_enu: FloatArray) -> tuple[
            float, FloatArray, FloatArray]:
        """Record the state at `t_s` and give the one `latency_s` old (the oldest kept when
        the run is younger than that): what the sensor delivers now, and when it was true."""
        self._past.append((t_s, pos_enu, reported_enu))
        while len(self._past) > 1 and self._past[1][0] <= t_s - self.cfg.latency_s + 1e-9:
            self._past.popleft()
        return self._past[0]

    def observe(self, observer_m: FloatArray, reported_m: FloatArray,
                target_m: FloatArray) -> FloatArray | None:
        """Where observer sees the target (ENU, 2), or None when it does not."""
        cfg = self.cfg
        offset = target_m - observer_m
        distance = math.hypot(float(offset[0]), float(offset[1]))
        if cfg.max_range_m is not None and distance > cfg.max_range_m:
            self.counters["sensing_out_of_range"] += 1
            return None
        if cfg.detect_prob < 1.0 and self.rng.random() >= cfg.detect_prob:
            self.counters["sensing_missed"] += 1
            return None
        if cfg.range_bearing:
            return self._range_bearing(distance, offset, reported_m)
        if cfg.noise_std_m > 0.0:
            return target_m + self.rng.normal(0.0, cfg.noise_std_m, 2)
        return target_m

    def _range_bearing(self, distance: float, offset: FloatArray,
                       reported_m: FloatArray) -> FloatArray:
        """Range with noise std, bearing with noise std / range (the same error across)."""
        std = self.cfg.noise_std_m
        bearing = math.atan2(float(offset[1]), float(offset[0]))
        if std > 0.0:
            distance = max(0.0, distance + float(self.rng.normal(0.0, std)))
            bearing += float(self.rng.normal(0.0, std / max(distance, 1.0)))
        return reported_m + distance * np.array([math.cos(bearing), math.sin(bearing)])
