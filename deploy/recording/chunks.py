"""A recorded run aligned on its truth grid chunk by chunk, from the assembler's spills.

`Assembly.chunks()` gives the `RunSeries` of consecutive runs of `chunk_rows` truth samples.
Per chunk it reads from disk only the truth rows of its stamps and the states stamped
between its first sample and the next chunk's; each follower's latest state before the
chunk is carried over from the one before, and its earliest state stands in before its
first (a "filled" sample).  Chunk by chunk the result is, bit for bit, what aligning the
whole run at once gives (tests/unit/test_recorder_assembler.py holds the two together),
and memory holds a chunk, never the run.
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.analysis.timeseries import RunSeries
from deploy.recording.spill import RowSpill

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
EPS_S = 1e-9
STATE_WIDTH = 7  # stamp, r x y, dr x y, u x y (the spill adds the follower index second)
_STATE_COLUMNS = [0, 2, 3, 4, 5, 6, 7]
CHUNK_VALUES = 1 << 17  # rows x followers per chunk: ~12 MB of series and errors


@dataclass(frozen=True)
class FollowerStats:
    """What the recorder saw of one follower's state stream."""

    states: int
    seq_gaps: int
    stale: int
    filled_samples: int  # truth samples taken before its first state (first state used)
    age_p50_ms: float | None  # age of the state used at each (unfilled) truth sample
    age_p99_ms: float | None

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass
class StateTally:
    """What the recorder counts of one follower's state stream as it goes."""

    states: int = 0
    gaps: int = 0
    stale: int = 0
    last_seq: dict[str, int] = field(default_factory=dict)
    first: FloatArray | None = None  # the earliest-stamped state (first arrival on ties)


def align_latest(query_s: FloatArray, stamps_s: FloatArray) -> tuple[IntArray, NDArray[np.bool_]]:
    """Index of the latest stamp <= each query (stamps sorted), and where none exists.

    Where none exists the index is 0: the first state stands in, flagged as filled.
    """
    idx = np.searchsorted(stamps_s, query_s + EPS_S, side="right").astype(np.int64) - 1
    filled = idx < 0
    idx[filled] = 0
    return idx, filled


def follower_columns(
    query_s: FloatArray, states: FloatArray, fill: FloatArray
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_], FloatArray]:
    """Estimate and command of one follower at each query, the queries before all of
    `states` (sorted by stamp, STATE_WIDTH columns; `fill` stands in there) and the age of
    the state used (s)."""
    if len(states):
        idx, filled = align_latest(query_s, states[:, 0])
        used = states[idx]
    else:
        filled = np.ones(len(query_s), dtype=bool)
        used = np.empty((len(query_s), STATE_WIDTH))
    used[filled] = fill
    # Each r_i is evaluated at the truth's instant, to first order with its own rate:
    # comparing a state up to one tick old with the present LAP would charge the
    # estimator for the sampling age (20 ms at 1 m/s is 2 cm).
    age_s = query_s - used[:, 0]
    lag_s = np.where(filled, 0.0, age_s)[:, None]
    return used[:, 1:3] + lag_s * used[:, 3:5], used[:, 5:7], filled, age_s


def truth_series(truth: FloatArray, t_s: FloatArray, est: FloatArray, cmd: FloatArray,
                 n: int) -> RunSeries:
    """A RunSeries from truth rows (stamp, follower xy..., target xy...) and aligned states."""
    k = len(truth)
    return RunSeries(t_s, truth[:, 1 : 1 + 2 * n].reshape(k, n, 2), est, cmd,
                     truth[:, 1 + 2 * n :].reshape(k, -1, 2))


def in_window(t_s: FloatArray, duration_s: float) -> NDArray[np.bool_]:
    return (t_s >= -EPS_S) & (t_s <= duration_s + EPS_S)


class _Ages:
    """Each follower's ages at use (ms), on disk until their percentiles are taken."""

    def __init__(self, spill_dir: Path | None) -> None:
        self._file = tempfile.TemporaryFile(dir=spill_dir)  # noqa: SIM115  # closed below
        self._parts: list[tuple[int, int, int]] = []  # follower, byte offset, count

    def add(self, i: int, ages_ms: FloatArray) -> None:
        if len(ages_ms):
            self._parts.append((i, self._file.seek(0, 2), len(ages_ms)))
            self._file.write(np.ascontiguousarray(ages_ms).tobytes())

    def percentiles(self, i: int) -> tuple[float | None, float | None]:
        parts = []
        for j, offset, count in self._parts:
            if j == i:
                self._file.seek(offset)
                parts.append(np.frombuffer(self._file.read(8 * count), dtype=np.float64))
        if not parts:
            return None, None
        ages = np.concatenate(parts)
        return float(np.percentile(ages, 50)), float(np.percentile(ages, 99))

    def close(self) -> None:
        self._file.close()


class Assembly:
    """The assembled run: its time grid, its series chunk by chunk (`chunks()`), and per
    follower the counters that qualify it (`followers`, once `chunks()` has run through)."""

    def __init__(self, truth: RowSpill, states: RowSpill, tallies: Sequence[StateTally],
                 stamps_s: FloatArray, start_stamp_s: float, duration_s: float,
                 start_source: str, silent: tuple[int, ...], chunk_rows: int | None = None,
                 spill_dir: Path | None = None) -> None:
        self.n = len(tallies)
        self.t_s = stamps_s - start_stamp_s
        self.start_stamp_s = start_stamp_s
        self.duration_s = duration_s  # planned, from the RunControl
        self.start_source = start_source  # "control", or "first_truth" without a start
        self.silent = silent  # 0-based followers that sent no state (NaN columns)
        self.series: RunSeries | None = None  # the whole of it, after `whole()`
        self._truth, self._states, self._tallies = truth, states, tallies
        self._stamps = stamps_s
        self._rows = chunk_rows or max(64, CHUNK_VALUES // max(1, self.n) // 64 * 64)
        self._spill_dir = spill_dir
        self._followers: tuple[FollowerStats, ...] | None = None

    @property
    def followers(self) -> tuple[FollowerStats, ...]:
        if self._followers is None:
            raise RuntimeError("the assembly's counters exist once chunks() has run through")
        return self._followers

    @property
    def filled_samples(self) -> int:
        return sum(f.filled_samples for f in self.followers)

    def chunks(self) -> Iterator[RunSeries]:
        """The series, `chunk_rows` truth samples at a time, in time order."""
        stamps, rows = self._stamps, self._rows
        heads = stamps[::rows]
        lows = heads + EPS_S  # chunk k takes the states stamped in (lows[k], highs[k]]
        highs = np.append(lows[1:], stamps[-1] + EPS_S)
        carry = self._carry(float(lows[0]))
        filled = [0] * self.n
        ages = _Ages(self._spill_dir)
        try:
            for k, lo in enumerate(range(0, len(stamps), rows)):
                query = stamps[lo : lo + rows]
                head_next = float(heads[k + 1]) if k + 1 < len(heads) else np.inf
                truth = self._truth_rows(query, head_next)
                states = self._state_rows(float(lows[k]), float(highs[k]))
                est = np.full((len(query), self.n, 2), np.nan)
                cmd = np.full((len(query), self.n, 2), np.nan)
                for i, tally in enumerate(self._tallies):
                    if tally.first is None:
                        continue
                    mine = states[states[:, 1] == i]
                    mine = mine[np.argsort(mine[:, 0], kind="stable")][:, _STATE_COLUMNS]
                    before = carry[i]
                    candidates = mine if before is None else np.vstack([before[None], mine])
                    est[:, i], cmd[:, i], was_filled, age_s = follower_columns(
                        query, candidates, tally.first)
                    if len(mine):
                        carry[i] = mine[-1]
                    filled[i] += int(was_filled.sum())
                    ages.add(i, 1000.0 * age_s[~was_filled])
                yield truth_series(truth, query - self.start_stamp_s, est, cmd, self.n)
            self._followers = tuple(
                FollowerStats(t.states, t.gaps, t.stale, filled[i], *ages.percentiles(i))
                for i, t in enumerate(self._tallies))
        finally:
            ages.close()

    def _carry(self, upto_s: float) -> list[FloatArray | None]:
        """Per follower, its latest state stamped at or before `upto_s` (the last to arrive
        of equal stamps, as a stable sort puts it), or None."""
        best: list[FloatArray | None] = [None] * self.n
        for block in self._states.blocks(-np.inf, upto_s):
            early = block[block[:, 0] <= upto_s]
            for i in np.unique(early[:, 1]).astype(int):
                mine = early[early[:, 1] == i]
                j = len(mine) - 1 - int(np.argmax(mine[::-1, 0]))
                held = best[i]
                if held is None or mine[j, 0] >= held[0]:
                    best[i] = mine[j, _STATE_COLUMNS]
        return best

    def _truth_rows(self, query: FloatArray, head_next: float) -> FloatArray:
        """The truth rows of `query`'s stamps, the first to arrive of a re-delivered one."""
        parts = [np.empty((0, self._truth.width))]
        for block in self._truth.blocks(float(query[0]), head_next):
            s = block[:, 0]
            keep = (s >= query[0]) & (s < head_next)
            keep &= in_window(s - self.start_stamp_s, self.duration_s)
            parts.append(block[keep])
        rows = np.concatenate(parts)
        _, first = np.unique(rows[:, 0], return_index=True)
        rows = rows[first]
        if not np.array_equal(rows[:, 0], query):  # the spill changed under us: a bug
            raise RuntimeError("truth rows do not match the assembled grid")
        return rows

    def _state_rows(self, after_s: float, upto_s: float) -> FloatArray:
        parts = [np.empty((0, self._states.width))]
        for block in self._states.blocks(after_s, upto_s):
            s = block[:, 0]
            parts.append(block[(s > after_s) & (s <= upto_s)])
        return np.concatenate(parts)


def whole(asm: Assembly) -> Assembly:
    """`asm` with `series` the whole run (every chunk in memory: short runs and tests)."""
    parts = list(asm.chunks())
    asm.series = RunSeries(*(np.concatenate([getattr(p, f.name) for p in parts])
                             for f in fields(RunSeries)))
    return asm
