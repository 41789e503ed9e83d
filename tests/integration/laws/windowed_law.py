"""The paper's law, but raising on every control tick of a window of the run's time
(`Inputs.t_s`): the vehicle holds there, lock-step and networked alike, and each engine
counts the failures (`law_failures`).  tests/integration/test_law_clock.py flies it."""

from __future__ import annotations

from agents.law.interface import Inputs, Output
from agents.law.paper import PaperLaw, PaperState

WINDOW_S = (20.0, 22.0)  # [from, to) seconds into the run


class WindowedLaw(PaperLaw):
    name = "windowed"

    def step(self, state: PaperState, inputs: Inputs) -> tuple[PaperState, Output]:
        if inputs.command and WINDOW_S[0] <= inputs.t_s < WINDOW_S[1]:
            raise RuntimeError(f"scheduled failure at t_s = {inputs.t_s:.3f} s")
        return super().step(state, inputs)
