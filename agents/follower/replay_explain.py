"""What a follower had in hand at its largest command jump, from a replay.

At every control tick of a replay (agents.follower.journal_replay) `JumpWatch` compares the
command with the last one; at the largest change it keeps the inputs of that tick: each
peer's message, new since the last control tick or not, and its age; the vehicle's
telemetry and each target's observation age; and the time since the last control tick
(a paused or descheduled process integrates a longer step)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from agents.law.interface import Peer, Sample


@dataclass(frozen=True)
class Jump:
    """The largest change of command between two control ticks, and why."""

    t_s: float  # the follower's clock
    size_m_s: float
    before_m_s: complex
    after_m_s: complex
    inputs: str  # what the law had in hand at that tick


class JumpWatch:
    """The largest command jump of one replay."""

    def __init__(self) -> None:
        self.largest: Jump | None = None
        self._arrived: set[int] = set()
        self._last: tuple[float, complex] | None = None

    def arrived(self, peers: Iterable[int]) -> None:
        """Peers whose message changed at a step (control or estimator)."""
        self._arrived.update(peers)

    def tick(self, now_s: float, u: complex, own: Sample, targets: Mapping[int, Sample],
             peers: Mapping[int, Peer]) -> None:
        last, self._last = self._last, (now_s, u)
        arrived, self._arrived = self._arrived, set()
        if last is None:
            return
        size = abs(u - last[1])
        if self.largest is not None and size <= self.largest.size_m_s:
            return
        parts = [f"{(now_s - last[0]) * 1e3:.0f} ms since the last control tick"]
        for j, p in peers.items():
            state = "new" if j in arrived else "no new message"
            parts.append(f"follower-{j}: {state}, estimate {(now_s - p.r.stamp_s) * 1e3:.0f} ms "
                         f"old, its vehicle's {(now_s - p.pos.stamp_s) * 1e3:.0f} ms old")
        parts.append(f"own telemetry {(now_s - own.stamp_s) * 1e3:.0f} ms old")
        for k, s in targets.items():
            parts.append(f"target-{k} seen {(now_s - s.stamp_s) * 1e3:.0f} ms ago")
        self.largest = Jump(now_s, size, last[1], u, "; ".join(parts))
