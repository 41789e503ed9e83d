"""The fixed-rate ticker on an injected clock: grid, phase, overruns (no real sleeping)."""

from __future__ import annotations

import pytest

from agents.shell.process import Ticker


class FakeClock:
    def __init__(self, t_s: float) -> None:
        self.t_s = t_s

    def __call__(self) -> float:
        return self.t_s

    def sleep(self, dt_s: float) -> None:
        assert dt_s >= 0.0
        self.t_s += dt_s


def test_ticks_fall_on_the_phased_grid() -> None:
    clock = FakeClock(100.003)
    ticker = Ticker(0.02, clock, clock.sleep, phase_s=0.005)
    times = [ticker.wait() for _ in range(5)]
    assert times == pytest.approx([100.005, 100.025, 100.045, 100.065, 100.085])
    assert ticker.overruns == 0 and ticker.ticks == 5


def test_a_late_tick_is_counted_and_not_caught_up() -> None:
    clock = FakeClock(10.0)
    ticker = Ticker(0.02, clock, clock.sleep)
    ticker.wait()
    clock.t_s += 0.1  # the loop body took five periods
    t = ticker.wait()
    assert ticker.overruns == 1
    assert t == pytest.approx(10.1)  # back on the grid at once, not five ticks in a burst
    assert ticker.wait() == pytest.approx(10.12)
