"""Assemble decoded bus messages into the `RunSeries` every metric reads (pure, no I/O).

The grid is the simulator's truth stream: one sample per `TruthSnapshot`, at experiment time
`t = truth stamp - start_stamp_s`, kept when `0 <= t <= duration_s`.  Each follower's estimate
and command at a sample are those of its latest `FollowerState` whose sender stamp is not after
the truth stamp -- sender stamps, never receive times, so network delay does not shift data.
Before a follower's first state its first state is used; such samples are counted as
"filled".  A follower that sent no state at all (it died or starved before its first) has
NaN estimates and commands: the run is kept, its metrics are over the others, and
`Assembly.silent` names it so that the verdict cannot call the run inside the bounds.
The age of the state used (truth stamp - state stamp) is what a benchmark reports as
"neighbour-state age at use".
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.core.timeseries import RunSeries
from transport.errors import DeployError
from transport.messages import FollowerState, Message, RunControl, TruthSnapshot

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
_EPS_S = 1e-9


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


@dataclass(frozen=True)
class Assembly:
    """The assembled run: the series and the counters that qualify it."""

    series: RunSeries
    followers: tuple[FollowerStats, ...]
    start_stamp_s: float
    duration_s: float  # planned, from the RunControl
    start_source: str  # "control", or "first_truth" when no start was heard
    silent: tuple[int, ...] = ()  # 0-based followers that sent no state (NaN columns)

    @property
    def filled_samples(self) -> int:
        return sum(f.filled_samples for f in self.followers)


@dataclass
class _StateLog:
    stamps_s: list[float]
    r_m: list[tuple[float, float]]
    u_m_s: list[tuple[float, float]]
    last_seq: dict[str, int]
    dr_m_s: list[tuple[float, float]] = field(default_factory=list)
    gaps: int = 0
    stale: int = 0


def align_latest(query_s: FloatArray, stamps_s: FloatArray) -> tuple[IntArray, NDArray[np.bool_]]:
    """Index of the latest stamp <= each query (stamps sorted), and where none exists.

    Where none exists the index is 0: the first state stands in, flagged as filled.
    """
    idx = np.searchsorted(stamps_s, query_s + _EPS_S, side="right").astype(np.int64) - 1
    filled = idx < 0
    idx[filled] = 0
    return idx, filled


class RunAssembler:
    """Fed decoded messages in any order; `build()` gives the run on the truth grid."""

    def __init__(self, n: int, m: int) -> None:
        self.n, self.m = n, m
        self.drops: Counter[str] = Counter()  # messages unusable for the series, per reason
        self.start: RunControl | None = None
        self.stopped = False
        self._truth_stamps_s: list[float] = []
        self._truth_pos_m: list[FloatArray] = []  # (n, 2) follower xy
        self._truth_tgt_m: list[FloatArray] = []  # (m, 2)
        self._states = [_StateLog([], [], [], {}) for _ in range(n)]

    # ---- feeding -------------------------------------------------------------------------
    def add(self, msg: Message) -> None:
        if isinstance(msg, TruthSnapshot):
            self._add_truth(msg)
        elif isinstance(msg, FollowerState):
            self._add_state(msg)
        elif isinstance(msg, RunControl):
            if msg.command == "start":
                self.start = msg
            elif msg.command == "stop":
                self.stopped = True

    def _add_truth(self, msg: TruthSnapshot) -> None:
        if len(msg.follower_pos_m) != self.n or len(msg.target_pos_m) != self.m:
            self.drops["truth_shape"] += 1
            return
        self._truth_stamps_s.append(msg.header.stamp_s)
        self._truth_pos_m.append(np.asarray(msg.follower_pos_m, dtype=np.float64)[:, :2])
        self._truth_tgt_m.append(np.asarray(msg.target_pos_m, dtype=np.float64))

    def _add_state(self, msg: FollowerState) -> None:
        if not 0 <= msg.index < self.n:
            self.drops["state_index"] += 1
            return
        log = self._states[msg.index]
        sender, seq = msg.header.sender_id, msg.header.seq
        last = log.last_seq.get(sender)
        if last is not None and seq <= last:
            log.stale += 1
        else:
            if last is not None:
                log.gaps += seq - last - 1
            log.last_seq[sender] = seq
        log.stamps_s.append(msg.header.stamp_s)
        log.r_m.append(msg.r_m)
        log.dr_m_s.append(msg.dr_m_s)
        log.u_m_s.append(msg.u_m_s)

    # ---- queries -------------------------------------------------------------------------
    @property
    def truth_count(self) -> int:
        return len(self._truth_stamps_s)

    def state_counts(self) -> list[int]:
        return [len(log.stamps_s) for log in self._states]

    def start_stamp_s(self) -> float | None:
        if self.start is not None:
            return self.start.start_stamp_s
        return min(self._truth_stamps_s) if self._truth_stamps_s else None

    def latest_experiment_time_s(self) -> float | None:
        start = self.start_stamp_s()
        if start is None or not self._truth_stamps_s:
            return None
        return self._truth_stamps_s[-1] - start

    def recent_series(self, window_s: float) -> RunSeries | None:
        """The last `window_s` of truth (by arrival) with states aligned: for live progress."""
        start = self.start_stamp_s()
        if start is None or not self._truth_stamps_s or all(not s.stamps_s for s in self._states):
            return None
        newest = self._truth_stamps_s[-1]
        k = len(self._truth_stamps_s)
        first = k - 1
        while first > 0 and self._truth_stamps_s[first - 1] >= newest - window_s:
            first -= 1
        rows = np.arange(first, k)
        series, _ = self._series(rows, start, tail_states=4 * (k - first) + 8, stats=False)
        return series

    # ---- the result ----------------------------------------------------------------------
    def build(self, duration_s: float | None = None) -> Assembly:
        """The run between start and start + duration; DeployError says why if impossible."""
        start = self.start_stamp_s()
        if start is None or not self._truth_stamps_s:
            raise DeployError("no truth samples were received: nothing to assemble")
        duration = duration_s if duration_s is not None else self._planned_duration_s()
        stamps = np.asarray(self._truth_stamps_s)
        t = stamps - start
        inside = np.nonzero((t >= -_EPS_S) & (t <= duration + _EPS_S))[0]
        # Sort by stamp and drop duplicated snapshots (a re-delivered message).
        _, first_of_each = np.unique(stamps[inside], return_index=True)
        rows = inside[first_of_each]
        if len(rows) == 0:
            raise DeployError(
                f"none of the {len(stamps)} truth samples lies in the experiment window "
                f"[{start:.3f}, {start + duration:.3f}] (sender clock)"
            )
        silent = tuple(i for i, log in enumerate(self._states) if not log.stamps_s)
        if len(silent) == self.n:
            raise DeployError("no follower sent a state: nothing to judge")
        series, stats = self._series(rows, start)
        source = "control" if self.start is not None else "first_truth"
        return Assembly(series, stats, start, duration, source, silent)

    def _planned_duration_s(self) -> float:
        if self.start is not None:
            return self.start.duration_s
        return max(self._truth_stamps_s) - min(self._truth_stamps_s)

    def _series(
        self, rows: IntArray, start_s: float, tail_states: int | None = None, stats: bool = True
    ) -> tuple[RunSeries, tuple[FollowerStats, ...]]:
        """The series on `rows` of the truth grid, and per follower its FollowerStats (empty
        without `stats`: live progress, once a second, needs none of their percentiles)."""
        stamps = np.asarray(self._truth_stamps_s)[rows]
        est = np.empty((len(rows), self.n, 2))
        cmd = np.empty((len(rows), self.n, 2))
        found: list[FollowerStats] = []
        for i, log in enumerate(self._states):
            if not log.stamps_s:
                est[:, i] = cmd[:, i] = np.nan
                if stats:
                    found.append(_stats(log, 0, np.empty(0)))
                continue
            lo = 0 if tail_states is None else max(0, len(log.stamps_s) - tail_states)
            s_stamps = np.asarray(log.stamps_s[lo:])
            order = np.argsort(s_stamps, kind="stable")
            idx, filled = align_latest(stamps, s_stamps[order])
            used = order[idx]
            # Each r_i is evaluated at the truth's instant, to first order with its own
            # rate: comparing a state up to one tick old with the present LAP would charge
            # the estimator for the sampling age (20 ms at 1 m/s is 2 cm).
            lag_s = np.where(filled, 0.0, stamps - s_stamps[used])[:, None]
            est[:, i] = np.asarray(log.r_m[lo:])[used] + lag_s * np.asarray(log.dr_m_s[lo:])[used]
            cmd[:, i] = np.asarray(log.u_m_s[lo:])[used]
            if stats:
                ages_ms = 1000.0 * (stamps - s_stamps[used])[~filled]
                found.append(_stats(log, int(filled.sum()), ages_ms))
        pos = np.stack([self._truth_pos_m[r] for r in rows])
        tgt = np.stack([self._truth_tgt_m[r] for r in rows])
        return RunSeries(stamps - start_s, pos, est, cmd, tgt), tuple(found)


def _stats(log: _StateLog, filled: int, ages_ms: FloatArray) -> FollowerStats:
    p50 = float(np.percentile(ages_ms, 50)) if ages_ms.size else None
    p99 = float(np.percentile(ages_ms, 99)) if ages_ms.size else None
    return FollowerStats(len(log.stamps_s), log.gaps, log.stale, filled, p50, p99)


def assembly_extra(asm: Assembly, drops: Counter[str]) -> dict[str, Any]:
    """The assembler's share of metrics.json."""
    return {
        "truth_samples": len(asm.series.t_s),
        "filled_samples": asm.filled_samples,
        "start_stamp_s": asm.start_stamp_s,
        "planned_duration_s": asm.duration_s,
        "start_source": asm.start_source,
        "followers": {str(i): f.as_dict() for i, f in enumerate(asm.followers)},
        "state_age_p50_ms": [f.age_p50_ms for f in asm.followers],
        "state_age_p99_ms": [f.age_p99_ms for f in asm.followers],
        "assembler_drops": dict(drops),
        "silent_followers": list(asm.silent),
    }
