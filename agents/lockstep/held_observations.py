"""Lock-step's limited sensor (`[sensing]`): the same `TargetSensor` as the simulator's, in
the same draw order (target by target, each target's observers in turn), so a seed misses
the same share.  A missed observation holds the follower's last one of that target, as a
follower holds a lost message.  A sensor with a range needs each follower's position as
the loop reaches it: `RangedSensing` draws step k's observations from the positions of
step k, one step of the loop at a time (agents.lockstep.engine)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from agents.scenario.model import Scenario
from agents.weather.target_sensor import TargetSensor

FloatArray = NDArray[np.float64]


def sensed_targets(scenario: Scenario, t: FloatArray,
                   targets: FloatArray) -> FloatArray | None:
    """(k, n, m, 2): what each follower holds of each target at each step (NaN for a target
    it does not observe); None without a limited sensor (exact observations)."""
    cfg = scenario.sensing
    if cfg is None or cfg.is_perfect or cfg.max_range_m is not None:
        return None  # exact, or drawn step by step (RangedSensing)
    sensor = TargetSensor(cfg)
    held = np.full((t.shape[0], scenario.n, scenario.m, 2), np.nan)
    last = np.full((scenario.n, scenario.m, 2), np.nan)
    zeros = np.zeros((scenario.n, 2))  # no range: where the observer is does not matter
    for k in range(t.shape[0]):
        _hold(scenario, sensor, float(t[k]), targets[k], zeros, zeros, last)
        held[k] = last
    return held


def _hold(scenario: Scenario, sensor: TargetSensor, t_s: float, targets: FloatArray,
          true_m: FloatArray, reported_m: FloatArray, last: FloatArray) -> None:
    """One step's draws into `last` (n, m, 2), in the simulator's order: what each follower
    sees of each target it observes, its last observation where it misses one."""
    _, seen_now, _ = sensor.remember(t_s, targets, targets)
    for j, spec in enumerate(scenario.targets):
        for i in spec.observed_by:
            seen = sensor.observe(true_m[i], reported_m[i], seen_now[j])
            if seen is not None or np.isnan(last[i, j, 0]):
                last[i, j] = seen_now[j] if seen is None else seen


class RangedSensing:
    """Step by step: what each follower holds of each target, drawn from where it is."""

    def __init__(self, scenario: Scenario, weights: FloatArray) -> None:
        assert scenario.sensing is not None
        self.scenario, self.weights = scenario, weights
        self.sensor = TargetSensor(scenario.sensing)
        self.last = np.full((scenario.n, scenario.m, 2), np.nan)

    def p_tilde(self, t_s: float, targets: FloatArray, true_m: FloatArray,
                reported_m: FloatArray) -> FloatArray:
        """(n, 2) p~ at `t_s` from the followers' true and reported positions (n, 2)."""
        _hold(self.scenario, self.sensor, t_s, targets, true_m, reported_m, self.last)
        return np.einsum("ij,ijd->id", self.weights, np.nan_to_num(self.last))


def held_p_tilde(held: FloatArray, weights: FloatArray) -> FloatArray:
    """(k, n, 2) p~ from what each follower holds: W @ held over its observed targets."""
    return np.einsum("ij,kijd->kid", weights, np.nan_to_num(held))
