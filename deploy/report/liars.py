"""Who lied in a run, and when it was first caught: from the followers' own counts.

Each follower counts the states of each neighbour it found implausible
(agents.follower.plausible: `implausible_f<j>` and `implausible_first_ms_f<j>`, the
experiment time of its first one).  Only the accuser saw what it counts, so a lying
follower could accuse an honest one; a follower is named a liar when at least
`NAMED_BY` followers accuse it (on a ring, both its neighbours), and only suspected when
one does.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

COUNT, FIRST = "implausible_f", "implausible_first_ms_f"
NAMED_BY = 2


@dataclass(frozen=True)
class Accused:
    """Follower `index` (0-based) and what its accusers said of it."""

    index: int
    accusers: tuple[str, ...]
    rejected: int  # its states refused, summed over the accusers
    first_s: float | None  # experiment time of the earliest refusal

    @property
    def named(self) -> bool:
        return len(self.accusers) >= NAMED_BY

    def text(self) -> str:
        when = "" if self.first_s is None else f", first at {self.first_s:.2f} s"
        who = ", ".join(self.accusers)
        me = f"follower-{self.index} (the scenario's follower {self.index + 1})"
        if self.named:
            return f"{me} lied: {self.rejected} states refused by {who}{when}"
        return f"{me} suspected by {who} only ({self.rejected} states{when})"


def accused(status: Mapping[str, Any]) -> tuple[Accused, ...]:
    """Every follower some follower refused a state of, most refused first; `status`
    maps process names to their last status counters (launch.json)."""
    by: dict[int, list[tuple[str, int, float | None]]] = {}
    for name, counters in status.items():
        if not (name.startswith("follower-") and isinstance(counters, Mapping)):
            continue
        for key, value in counters.items():
            if not (isinstance(key, str) and key.startswith(COUNT) and key[len(COUNT):]
                    .isdigit() and isinstance(value, int) and value > 0):
                continue
            j = int(key[len(COUNT):])
            first = counters.get(f"{FIRST}{j}")
            first_s = first / 1000.0 if isinstance(first, int) and first > 0 else None
            by.setdefault(j, []).append((name, value, first_s))
    out = []
    for j, said in by.items():
        times = [t for _, _, t in said if t is not None]
        out.append(Accused(j, tuple(sorted(n for n, _, _ in said)), sum(v for _, v, _ in said),
                           min(times) if times else None))
    return tuple(sorted(out, key=lambda a: (-len(a.accusers), -a.rejected, a.index)))


def liar_lines(launch: Mapping[str, Any]) -> tuple[str, ...]:
    """The verdict's lines about liars, from launch.json; empty when nobody was refused."""
    status = launch.get("status_at_stop") or launch.get("status")
    return tuple(a.text() for a in accused(status)) if isinstance(status, Mapping) else ()
