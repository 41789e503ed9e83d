"""Vehicle-to-agent clock offset from MAVLink TIMESYNC round trips: pure, times are arguments.

A request leaves at agent time `sent_s` (its ts1), the vehicle stamps the reply with
its boot clock `vehicle_s` (tc1), the reply arrives at agent time `received_s`.  The
sample  offset = (sent_s + received_s) / 2 - vehicle_s  (agent minus vehicle) is off
by at most half the round trip, less the shorter the round trip is.

PX4 and MAVROS keep a double-exponential filter whose gains slide from 0.05 to 0.003
over 500 samples and reset after 5 samples deviating by more than 100 ms: after a
jump they go 50 s without synced stamps (/work notes, measured).  Here:
- each sample's offset is the minimum-round-trip one of the last `window` samples
  (carried to now with the skew): queueing delay only ever adds, so the fastest
  round trip is the truest;
- a Holt filter (offset and skew) smooths those picks, for slow drift only;
- `jump_samples` consecutive samples that disagree with the estimate by more than
  `jump_s` beyond their own half round trip re-lock it from those samples alone: a
  jump or a reboot costs a few samples, not a minute.  Each re-lock is counted.
Samples slower than `max_rtt_s` or with a negative round trip say nothing and are
dropped (and counted): e.g. replies that waited in our socket while we were paused.
"""

from __future__ import annotations

import logging
import math
from collections import Counter, deque
from dataclasses import dataclass

log = logging.getLogger(__name__)
MAX_SKEW = 1e-3  # no quartz is off by more than 1000 ppm: a larger skew is noise


@dataclass(frozen=True)
class TimesyncParams:
    window: int = 8  # samples among which the fastest round trip is picked
    lock_samples: int = 3  # samples before the estimate is used
    max_rtt_s: float = 0.05
    jump_s: float = 0.01  # disagreement beyond half the round trip that suggests a jump
    jump_samples: int = 3  # consecutive disagreeing samples that re-lock
    alpha: float = 0.3  # Holt gain of the offset
    beta: float = 0.05  # Holt gain of the skew

    def __post_init__(self) -> None:
        if self.window < 1 or self.lock_samples < 1 or self.jump_samples < 1:
            raise ValueError("window, lock_samples and jump_samples must be >= 1")
        if not (0.0 < self.alpha <= 1.0 and 0.0 <= self.beta <= 1.0):
            raise ValueError("alpha must be in (0, 1], beta in [0, 1]")
        if not (self.max_rtt_s > 0.0 and self.jump_s > 0.0):
            raise ValueError("max_rtt_s and jump_s must be > 0")


@dataclass(frozen=True)
class _Sample:
    mid_s: float  # agent time half-way through the round trip
    rtt_s: float
    offset_s: float  # agent minus vehicle


class TimesyncEstimator:
    """offset_at(t) = agent time minus vehicle time, once `locked`."""

    def __init__(self, params: TimesyncParams | None = None, name: str = "vehicle") -> None:
        self.params = params or TimesyncParams()
        self.name = name
        self.counters: Counter[str] = Counter()
        self.resets = 0
        self._window: deque[_Sample] = deque(maxlen=self.params.window)
        self._deviating: list[_Sample] = []
        self._offset_s = 0.0
        self._skew = 0.0
        self._ref_s = 0.0
        self.locked = False

    def offset_at(self, t_s: float) -> float:
        return self._offset_s + self._skew * (t_s - self._ref_s)

    @property
    def skew(self) -> float:
        return self._skew

    def reset(self, why: str) -> None:
        """Forget everything (the vehicle rebooted); counted."""
        self._window.clear()
        self._deviating = []
        self.locked = False
        self.resets += 1
        log.warning("%s clock: timesync reset (%s)", self.name, why)

    def add(self, sent_s: float, vehicle_s: float, received_s: float) -> bool:
        """Fold one round trip in; False when it was dropped."""
        rtt = received_s - sent_s
        if not all(map(math.isfinite, (sent_s, vehicle_s, received_s))) or \
                not 0.0 <= rtt <= self.params.max_rtt_s:
            self.counters["timesync_dropped_rtt"] += 1
            return False
        s = _Sample(0.5 * (sent_s + received_s), rtt, 0.5 * (sent_s + received_s) - vehicle_s)
        if self.locked and self._deviates(s):
            self._deviating.append(s)
            if len(self._deviating) < self.params.jump_samples:
                return True
            self._relock(s)
            return True
        self._deviating = []
        self._window.append(s)
        self._update(s.mid_s)
        return True

    def _deviates(self, s: _Sample) -> bool:
        return abs(s.offset_s - self.offset_at(s.mid_s)) > self.params.jump_s + 0.5 * s.rtt_s

    def _relock(self, s: _Sample) -> None:
        jump = s.offset_s - self.offset_at(s.mid_s)
        self.resets += 1
        self.counters["timesync_relocks"] += 1
        log.warning("%s clock jumped by %+.3f s: timesync re-locked from %d samples",
                    self.name, jump, len(self._deviating))
        self._window.clear()
        self._window.extend(self._deviating)
        self._deviating = []
        self.locked = False
        self._update(s.mid_s)

    def _pick(self, t_s: float) -> float:
        best = min(self._window, key=lambda w: w.rtt_s)
        return best.offset_s + self._skew * (t_s - best.mid_s)

    def _update(self, t_s: float) -> None:
        pick = self._pick(t_s)
        if not self.locked:
            if len(self._window) >= self.params.lock_samples:
                self.locked = True
                self.counters["timesync_locks"] += 1
            self._offset_s, self._ref_s = pick, t_s
            return
        dt = t_s - self._ref_s
        predicted = self.offset_at(t_s)
        level = predicted + self.params.alpha * (pick - predicted)
        if dt > 0.0:
            trend = (level - self._offset_s) / dt
            skew = self._skew + self.params.beta * (trend - self._skew)
            self._skew = min(MAX_SKEW, max(-MAX_SKEW, skew))
        self._offset_s, self._ref_s = level, max(t_s, self._ref_s)
