"""The network faults of a run on its timeline, as one receiver sees them.

`NetTimeline(faults, receiver)` answers, at a bus time, whether the link from follower j
into this receiver is cut (a partition or isolation window holds them apart) and which
degradation, if any, replaces its impairment.  Its origin is the experiment's start on
the bus clock (the start word), set once known; before it no fault holds.  A window is
[origin + at_s, origin + at_s + duration_s).  When two degradations overlap on a link the
one that started last holds.

`cut_alive_watch` is the liveliness a real cut would show: a follower's token is hidden
while its link into this receiver is cut (it vanishes, then appears again at the heal
if it is still alive), so membership (agents.membership.liveness) drops and takes back the other
side exactly as Zenoh would after a lost session.  Only follower tokens are filtered
(`HidingAliveWatch`; a cut between hosts hides them the same way: transport.clock_sync).
"""

from __future__ import annotations

from collections.abc import Callable

from transport.bus import AliveEvent, AliveWatch
from transport.key_exprs import parse_key
from transport.network_schema import LinkImpairment, NetFault


class NetTimeline:
    """The network faults applying to the links into `receiver` (0-based follower)."""

    def __init__(self, faults: tuple[NetFault, ...], receiver: int) -> None:
        self.faults, self.receiver = faults, receiver
        self.origin_s: float | None = None

    def set_origin(self, origin_s: float) -> None:
        """The experiment's start on the bus clock; the first one given holds."""
        if self.origin_s is None:
            self.origin_s = origin_s

    def _active(self, now_s: float) -> list[NetFault]:
        if self.origin_s is None:
            return []
        t = now_s - self.origin_s
        return [f for f in self.faults if f.at_s <= t < f.end_s]

    def cut(self, sender: int, now_s: float) -> bool:
        """True when follower `sender` cannot be heard here at `now_s`."""
        return any(separates(f, sender, self.receiver) for f in self._active(now_s))

    def degradation(self, sender: int, now_s: float) -> tuple[int, LinkImpairment] | None:
        """(fault number, impairment) of the degradation on link sender -> receiver now."""
        active = self._active(now_s)
        found = [k for k, f in enumerate(self.faults) if f.action == "degrade" and f in active
                 and (not f.links or (sender, self.receiver) in f.links)]
        if not found:
            return None
        last = max(found, key=lambda k: (self.faults[k].at_s, k))
        return last, self.faults[last].impairment


def separates(fault: NetFault, a: int, b: int) -> bool:
    """True when `fault` (a partition or isolation) puts followers a and b apart."""
    if a == b or fault.action == "degrade":
        return False
    return side(fault, a) != side(fault, b)


def side(fault: NetFault, k: int) -> int:
    """Follower k's side of a partition (its group's number; -1: the followers named in
    no group, one more group) or an isolation (0: the isolated one, 1: the others)."""
    if fault.action == "isolate":
        return 0 if fault.groups and k in fault.groups[0] else 1
    for g, members in enumerate(fault.groups):
        if k in members:
            return g
    return -1


class HidingAliveWatch:
    """An AliveWatch that hides the follower tokens `hidden(index, now_s)` says are out of
    reach now: each vanishes when it goes out of reach and appears again when back in reach
    (if still alive), as Zenoh would show them across a lost session."""

    def __init__(self, inner: AliveWatch, hidden: Callable[[int, float], bool],
                 clock: Callable[[], float]) -> None:
        self.key_expr = inner.key_expr
        self._inner, self._hidden_index, self._clock = inner, hidden, clock
        self._real: set[str] = set()
        self._shown: set[str] = set()

    def _hidden(self, key: str, now_s: float) -> bool:
        info = parse_key(key)
        if info is None or info.role != "follower" or info.index is None:
            return False
        return self._hidden_index(info.index, now_s)

    def drain_events(self) -> list[AliveEvent]:
        for ev in self._inner.drain_events():
            (self._real.add if ev.alive else self._real.discard)(ev.key)
        now = self._clock()
        shown = {k for k in self._real if not self._hidden(k, now)}
        events = [AliveEvent(k, False) for k in sorted(self._shown - shown)]
        events += [AliveEvent(k, True) for k in sorted(shown - self._shown)]
        self._shown = shown
        return events

    def poll(self) -> frozenset[str]:
        self.drain_events()
        return frozenset(self._shown)

    def close(self) -> None:
        self._inner.close()


def cut_alive_watch(inner: AliveWatch, timeline: NetTimeline,
                    clock: Callable[[], float]) -> HidingAliveWatch:
    """The tokens of the followers whose link into us is cut now, hidden."""
    return HidingAliveWatch(inner, timeline.cut, clock)
