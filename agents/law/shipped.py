"""The laws enclose ships, by the name a scenario's `[law]` table gives."""

from __future__ import annotations

from typing import Any

from agents.law.interface import Law
from agents.law.paper import PaperLaw

SHIPPED: dict[str, type[Law[Any]]] = {PaperLaw.name: PaperLaw}
