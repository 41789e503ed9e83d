"""The one time-series layout every kind of run produces and every metric reads."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RunSeries:
    """Samples on one time grid; follower-indexed arrays are (k, n, ...), targets (k, m, 2)."""

    t_s: FloatArray  # (k,)
    follower_pos_m: FloatArray  # (k, n, 2) true positions
    estimate_m: FloatArray  # (k, n, 2) each follower's r_i
    command_m_s: FloatArray  # (k, n, 2) velocity commands u_i
    target_pos_m: FloatArray  # (k, m, 2) true target positions

    @property
    def lap_m(self) -> FloatArray:
        """(k, 2) true leaders' average position."""
        return np.asarray(self.target_pos_m.mean(axis=1))

    def decimate(self, every: int) -> RunSeries:
        """Every `every`-th sample (and always the last one)."""
        idx = np.unique(np.append(np.arange(0, len(self.t_s), max(1, every)), len(self.t_s) - 1))
        return RunSeries(
            self.t_s[idx],
            self.follower_pos_m[idx],
            self.estimate_m[idx],
            self.command_m_s[idx],
            self.target_pos_m[idx],
        )
