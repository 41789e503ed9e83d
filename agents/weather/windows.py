"""Gust windows on the timeline (`[[faults]] action = "wind"`): the gusts' strength at a
time, and the signals by which the launcher opens and closes a window in the simulator
(deploy.launch.fault_injector), as it starts and ends a lie (agents.follower.lie)."""

from __future__ import annotations

import signal

from agents.scenario.faults import FaultSpec

# Past the lie's signals (SIGRTMIN + 0..4, agents.follower.lie), which go to followers only.
_FIRST = 10


def wind_begin_signal() -> int:
    return int(signal.SIGRTMIN) + _FIRST


def wind_end_signal() -> int:
    return int(signal.SIGRTMIN) + _FIRST + 1


def wind_windows(faults: tuple[FaultSpec, ...]) -> tuple[FaultSpec, ...]:
    return tuple(f for f in faults if f.action == "wind")


def window_strengths(faults: tuple[FaultSpec, ...]) -> tuple[float, ...]:
    """The gust windows' strengths in time order: what the simulator is told."""
    return tuple(f.gust_std_m_s or 0.0 for f in sorted(wind_windows(faults), key=lambda f: f.at_s))


def gust_std_at(windows: tuple[FaultSpec, ...], t_s: float, base_m_s: float) -> float:
    """The gusts' strength at experiment time `t_s`: the latest window open then, else base."""
    std = base_m_s
    for f in windows:
        if f.at_s <= t_s < f.at_s + (f.duration_s or 0.0) and f.gust_std_m_s is not None:
            std = f.gust_std_m_s
    return std


class WindSchedule:
    """The simulator's side: each begin signal opens the next window in time order, the end
    signal closes it (the launcher knows the experiment's clock; the simulator does not)."""

    def __init__(self, strengths: tuple[float, ...], base_m_s: float) -> None:
        self.strengths = strengths  # each window's, in time order
        self.base_m_s = base_m_s
        self.opened = 0
        self.std_m_s = base_m_s

    def begin(self) -> None:
        if self.opened < len(self.strengths):
            self.std_m_s = self.strengths[self.opened]
            self.opened += 1

    def end(self) -> None:
        self.std_m_s = self.base_m_s
