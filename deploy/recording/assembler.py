"""Assemble decoded bus messages into the `RunSeries` every metric reads.

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

Memory does not grow with the run: truth and states go to `RowSpill`s on disk as they
arrive, and only the last seconds stay in memory for live progress (`recent_series`).
`assemble()` aligns the run chunk by chunk of the truth grid (deploy.recording.chunks).
"""

from __future__ import annotations

from collections import Counter, deque
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.analysis.timeseries import RunSeries
from deploy.recording.chunks import (
    STATE_WIDTH,
    Assembly,
    FollowerStats,
    StateTally,
    align_latest,
    follower_columns,
    in_window,
    truth_series,
    whole,
)
from deploy.recording.spill import BLOCK_ROWS, RowSpill
from errors import DeployError
from transport.messages import FollowerState, Message, RunControl, TruthSnapshot

__all__ = ["Assembly", "FollowerStats", "RunAssembler", "align_latest", "assembly_extra"]

FloatArray = NDArray[np.float64]
RECENT_TRUTH = 512  # truth rows kept for live progress: 10 s at 50 Hz
RECENT_STATES = 512  # states per follower kept for it: its 1-s window needs 4 per row
MAX_SENDERS = 16  # sequence tallies per follower index (a restart may bring a new sender)


class RunAssembler:
    """Fed decoded messages in any order; `assemble()` gives the run on the truth grid.

    `spill_dir`: where the spilled rows go (anonymous temporary files; the system's
    temporary directory if None).
    """

    def __init__(self, n: int, m: int, spill_dir: Path | None = None,
                 block_rows: int = BLOCK_ROWS, recent_from_adds: bool = True) -> None:
        self.n, self.m = n, m
        # False: states come late, in batches (deploy.recording.intake), and the live
        # progress gets the newest ones through `note_recent` instead.
        self.recent_from_adds = recent_from_adds
        self.spill_dir = spill_dir
        self.drops: Counter[str] = Counter()  # messages unusable for the series, per reason
        self.start: RunControl | None = None
        self.stopped = False
        # stamp, xy per follower, xy per target; and stamp, index, r, dr, u
        self.truth = RowSpill(1 + 2 * n + 2 * m, spill_dir, block_rows)
        self.states = RowSpill(STATE_WIDTH + 1, spill_dir, block_rows)
        self.tallies = [StateTally() for _ in range(n)]
        self._recent_truth: deque[FloatArray] = deque(maxlen=RECENT_TRUTH)
        self._recent_states: list[deque[tuple[float, ...]]] = [
            deque(maxlen=RECENT_STATES) for _ in range(n)]
        self._truth_min_s = np.inf
        self._truth_max_s = -np.inf
        self._truth_last_s: float | None = None  # of the last to arrive

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
        stamp = msg.header.stamp_s
        row = np.empty(self.truth.width)
        row[0] = stamp
        try:
            row[1 : 1 + 2 * self.n] = np.asarray(msg.follower_pos_m,
                                                 dtype=np.float64)[:, :2].ravel()
            row[1 + 2 * self.n :] = np.asarray(msg.target_pos_m, dtype=np.float64).ravel()
        except (ValueError, TypeError, IndexError):  # not vectors of the expected sizes
            self.drops["truth_shape"] += 1
            return
        self.truth.append(row)
        self._recent_truth.append(row)
        self._truth_min_s = min(self._truth_min_s, stamp)
        self._truth_max_s = max(self._truth_max_s, stamp)
        self._truth_last_s = stamp

    def _add_state(self, msg: FollowerState) -> None:
        if not 0 <= msg.index < self.n:
            self.drops["state_index"] += 1
            return
        if not len(msg.r_m) == len(msg.dr_m_s) == len(msg.u_m_s) == 2:
            self.drops["state_shape"] += 1
            return
        tally = self.tallies[msg.index]
        sender, seq = msg.header.sender_id, msg.header.seq
        last = tally.last_seq.get(sender)
        if last is not None and seq <= last:
            tally.stale += 1
        else:
            if last is not None:
                tally.gaps += seq - last - 1
            elif len(tally.last_seq) >= MAX_SENDERS:
                del tally.last_seq[next(iter(tally.last_seq))]
            tally.last_seq[sender] = seq
        stamp = msg.header.stamp_s
        (rx, ry), (dx, dy), (ux, uy) = msg.r_m, msg.dr_m_s, msg.u_m_s
        self.states.append((stamp, msg.index, rx, ry, dx, dy, ux, uy))
        row = (stamp, rx, ry, dx, dy, ux, uy)
        if self.recent_from_adds:
            self._recent_states[msg.index].append(row)
        tally.states += 1
        if tally.first is None or stamp < tally.first[0]:
            tally.first = np.asarray(row, dtype=np.float64)

    def note_recent(self, msg: FollowerState) -> None:
        """A state for the live progress only (`recent_series`), not the run's series."""
        if 0 <= msg.index < self.n and len(msg.r_m) == len(msg.dr_m_s) == len(msg.u_m_s) == 2:
            (rx, ry), (dx, dy), (ux, uy) = msg.r_m, msg.dr_m_s, msg.u_m_s
            self._recent_states[msg.index].append((msg.header.stamp_s, rx, ry, dx, dy, ux, uy))

    # ---- queries -------------------------------------------------------------------------
    @property
    def truth_count(self) -> int:
        return self.truth.rows

    def state_counts(self) -> list[int]:
        return [t.states for t in self.tallies]

    def start_stamp_s(self) -> float | None:
        if self.start is not None:
            return self.start.start_stamp_s
        return self._truth_min_s if self.truth.rows else None

    def latest_experiment_time_s(self) -> float | None:
        start = self.start_stamp_s()
        if start is None or self._truth_last_s is None:
            return None
        return self._truth_last_s - start

    def recent_series(self, window_s: float) -> RunSeries | None:
        """The last `window_s` of truth (by arrival) with states aligned: for live progress."""
        start = self.start_stamp_s()
        if start is None or not self.truth.rows or not any(self._recent_states):
            return None
        truth = np.asarray(self._recent_truth)
        stamps = truth[:, 0]
        newest, first = stamps[-1], len(stamps) - 1
        while first > 0 and stamps[first - 1] >= newest - window_s:
            first -= 1
        truth, stamps = truth[first:], stamps[first:]
        est = np.full((len(stamps), self.n, 2), np.nan)
        cmd = np.full((len(stamps), self.n, 2), np.nan)
        for i, ring in enumerate(self._recent_states):
            if not ring:
                continue
            tail = np.asarray(list(ring)[-(4 * len(stamps) + 8) :])
            tail = tail[np.argsort(tail[:, 0], kind="stable")]
            est[:, i], cmd[:, i], _, _ = follower_columns(stamps, tail, tail[0])
        return truth_series(truth, stamps - start, est, cmd, self.n)

    # ---- the result ----------------------------------------------------------------------
    def assemble(self, duration_s: float | None = None,
                 chunk_rows: int | None = None) -> Assembly:
        """The run between start and start + duration, to be read chunk by chunk;
        DeployError says why if impossible."""
        start = self.start_stamp_s()
        if start is None or not self.truth.rows:
            raise DeployError("no truth samples were received: nothing to assemble")
        duration = duration_s if duration_s is not None else self._planned_duration_s()
        inside = [k[in_window(k - start, duration)] for k in self.truth.key_blocks()]
        # Sorted, and a re-delivered snapshot once.
        stamps = np.unique(np.concatenate(inside))
        if len(stamps) == 0:
            raise DeployError(
                f"none of the {self.truth.rows} truth samples lies in the experiment window "
                f"[{start:.3f}, {start + duration:.3f}] (sender clock)"
            )
        silent = tuple(i for i, t in enumerate(self.tallies) if not t.states)
        if len(silent) == self.n:
            raise DeployError("no follower sent a state: nothing to judge")
        source = "control" if self.start is not None else "first_truth"
        return Assembly(self.truth, self.states, self.tallies, stamps, start, duration,
                        source, silent, chunk_rows, self.spill_dir)

    def build(self, duration_s: float | None = None) -> Assembly:
        """`assemble()` read whole: for short runs and tests (`Assembly.series`)."""
        return whole(self.assemble(duration_s))

    def _planned_duration_s(self) -> float:
        if self.start is not None:
            return self.start.duration_s
        return float(self._truth_max_s - self._truth_min_s)

    def close(self) -> None:
        self.truth.close()
        self.states.close()


def assembly_extra(asm: Assembly, drops: Counter[str]) -> dict[str, Any]:
    """The assembler's share of metrics.json (once the assembly has been read through)."""
    return {
        "truth_samples": len(asm.t_s),
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
