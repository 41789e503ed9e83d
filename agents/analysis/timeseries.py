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
        return self.take(decimated_rows(0, len(self.t_s), every, len(self.t_s)))

    def take(self, rows: NDArray[np.int64]) -> RunSeries:
        """The samples at `rows` (indices, in order)."""
        return RunSeries(
            self.t_s[rows],
            self.follower_pos_m[rows],
            self.estimate_m[rows],
            self.command_m_s[rows],
            self.target_pos_m[rows],
        )


def decimated_rows(offset: int, count: int, every: int, total: int) -> NDArray[np.int64]:
    """Of the rows offset..offset+count-1 of a series of `total`, as indices from `offset`,
    those `decimate(every)` keeps: every `every`-th and the last."""
    every = max(1, every)
    first = -offset % every
    rows = np.arange(first, count, every, dtype=np.int64)
    if offset <= total - 1 < offset + count and (total - 1) % every:
        rows = np.append(rows, total - 1 - offset)
    return rows
