"""Live health of each link, from the followers' status counters (pure, no I/O).

A follower's ProcessStatus (about once a second) carries, per link L into it, `rx_L` (unique
messages received), `seq_last_L` and the age percentiles (`transport.link_stats`).  Between
two statuses of the receiver, the delivered ratio of the window is the new unique messages
over the new sequence numbers the sender used: `d rx / d seq_last` -- both counted by the
receiver, so the two followers' status clocks do not mix.  The whole-run figures are those
of metrics.json "links" (`deploy.recording.links.link_entry`).

Health, for colouring: "good" (window ratio >= 0.9 and median age <= 100 ms), "bad"
(window ratio < 0.5, median age > 500 ms, or nothing new from the sender in the window),
else "degraded".
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from deploy.recording.links import link_entry
from transport.link_stats import SENSOR
from transport.messages import ProcessStatus

GOOD_RATIO = 0.9
BAD_RATIO = 0.5
GOOD_AGE_MS = 100.0
BAD_AGE_MS = 500.0


@dataclass(frozen=True)
class LinkLive:
    """One link into a follower as shown live: `"f0->f2"` or `"sensor->f2"`."""

    name: str
    sender: int | None  # follower index; None for the simulator's sensor
    receiver: int
    rx: int
    delivered_ratio: float | None  # whole run so far
    window_delivered_ratio: float | None  # since the receiver's previous status
    age_p50_ms: float | None
    age_p99_ms: float | None
    health: str

    def as_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


def health(window_ratio: float | None, age_p50_ms: float | None) -> str:
    if window_ratio is None or window_ratio < BAD_RATIO:
        return "bad"
    if age_p50_ms is not None and age_p50_ms > BAD_AGE_MS:
        return "bad"
    if window_ratio >= GOOD_RATIO and (age_p50_ms is None or age_p50_ms <= GOOD_AGE_MS):
        return "good"
    return "degraded"


def _window_ratio(now: tuple[int, int], before: tuple[int, int] | None) -> float | None:
    if before is None:
        return None
    d_rx, d_seq = now[0] - before[0], now[1] - before[1]
    return None if d_seq <= 0 else max(0.0, min(1.0, d_rx / d_seq))


class LinkTracker:
    """The links of the latest follower statuses, with their window since the previous one."""

    def __init__(self) -> None:
        self._previous: dict[tuple[int, str], tuple[int, int]] = {}  # (receiver, link) -> rx, seq
        self._links: dict[tuple[int, str], LinkLive] = {}

    def update(self, status: ProcessStatus, statuses: Mapping[int, ProcessStatus],
               recorded_states: Sequence[int]) -> None:
        """A follower status arrived (`statuses` holds the latest of every follower)."""
        c, i = status.counters, status.index
        names = [k[3:] for k in c if k.startswith("rx_") and not k.startswith("rx_dup")]
        for name in names:
            entry = link_entry(name, c, statuses, recorded_states)
            now = (int(c[f"rx_{name}"]), int(c.get(f"seq_last_{name}", 0)))
            window = _window_ratio(now, self._previous.get((i, name)))
            self._previous[(i, name)] = now
            sender = None if name == SENSOR else int(name[1:])
            self._links[(i, name)] = LinkLive(
                f"{name}->f{i}", sender, i, entry["rx"], entry["delivered_ratio"], window,
                entry["age_p50_ms"], entry["age_p99_ms"], health(window, entry["age_p50_ms"]))

    def links(self) -> list[LinkLive]:
        return [self._links[k] for k in sorted(self._links)]
