"""The process clock: wall time, or wall time with an injected offset and drift.

Processes on several hosts stamp with clocks that differ (an offset of seconds, a drift
of up to 100 ppm).  To test that data stamped on one host are aged correctly on another
without several machines, a process can be given a skewed clock through its environment:

    ENCLOSE_CLOCK_OFFSET_S=1.3 ENCLOSE_CLOCK_DRIFT_PPM=50 python -m agents.follower.main ...

Every stamp the process makes (bus.now_s(), hence headers, ticks, the MAVLink clock map)
then comes from this clock.  Used by tests and `enclose run --hosts K` only; unset, the
clock is `time.time`.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from errors import ConfigError

Clock = Callable[[], float]
ENV_OFFSET_S = "ENCLOSE_CLOCK_OFFSET_S"
ENV_DRIFT_PPM = "ENCLOSE_CLOCK_DRIFT_PPM"
MAX_DRIFT_PPM = 1000.0


@dataclass(frozen=True)
class SkewedClock:
    """base() + offset_s + (base() - origin_s) * drift_ppm * 1e-6."""

    offset_s: float = 0.0
    drift_ppm: float = 0.0
    base: Clock = time.time
    origin_s: float = field(default_factory=time.time)

    def __post_init__(self) -> None:
        if not math.isfinite(self.offset_s):
            raise ConfigError(ENV_OFFSET_S, f"{self.offset_s} is not a finite number of seconds")
        if not (math.isfinite(self.drift_ppm) and abs(self.drift_ppm) <= MAX_DRIFT_PPM):
            raise ConfigError(ENV_DRIFT_PPM, f"{self.drift_ppm} not within +-{MAX_DRIFT_PPM}")

    def __call__(self) -> float:
        t = self.base()
        return t + self.offset_s + (t - self.origin_s) * self.drift_ppm * 1e-6


def _number(env: Mapping[str, str], name: str) -> float:
    raw = env.get(name, "").strip()
    if not raw:
        return 0.0
    try:
        return float(raw)
    except ValueError:
        raise ConfigError(name, f"{raw!r} is not a number") from None


def process_clock(env: Mapping[str, str] | None = None) -> Clock:
    """This process's clock: `time.time` unless the environment injects an offset/drift."""
    env = os.environ if env is None else env
    offset_s, drift_ppm = _number(env, ENV_OFFSET_S), _number(env, ENV_DRIFT_PPM)
    if offset_s == 0.0 and drift_ppm == 0.0:
        return time.time
    return SkewedClock(offset_s, drift_ppm)


def clock_env(offset_s: float, drift_ppm: float = 0.0) -> dict[str, str]:
    """The environment entries that give a child process this clock."""
    return {ENV_OFFSET_S: repr(float(offset_s)), ENV_DRIFT_PPM: repr(float(drift_ppm))}
