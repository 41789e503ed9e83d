"""A scenario's law, built: `make_law(scenario)` is the one way a process gets its law
object (each follower, the recorder that checks their states).  The scenario's own
choice of law is its [law] table; without one, the paper's."""

from __future__ import annotations

from typing import Any

from agents.law.interface import Law
from agents.law.paper import PaperLaw
from agents.scenario.model import Scenario


def make_law(scenario: Scenario) -> Law[Any]:
    """The law of `scenario`, its published fields checked (ScenarioError naming the law)."""
    law = PaperLaw.from_params({}, scenario)
    law.declared()
    return law
