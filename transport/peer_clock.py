"""Per-peer clock offsets, estimated from the message exchange, and stamps mapped with them.

Every process publishes clock probes (transport.clock_sync) and echoes, in each probe,
the newest probe it heard from every peer with its own receive time.  A probe from peer
P that echoes ours gives NTP's four times (t1 our send, t2 P's receive, t3 P's send,
t4 our receive) and one sample

    offset = ((t2 - t1) + (t3 - t4)) / 2     (P's clock minus ours)
    delay  = (t4 - t1) - (t3 - t2)           (the round trip, without P's hold time)

The offset of a sample is off by half the asymmetry of its two one-way delays, at most
half its delay: the least-delayed sample of a recent window is the best one (NTP's
clock filter; the same windowed minimum as the vehicle clock map, agents.mavlink.timemap).
The window (WINDOW_S) forgets, so drift (100 ppm: 0.1 ms/s) costs at most WINDOW_S * drift;
among samples within DELAY_SLACK_S of the window's least delay the newest wins, which
follows drift closer still.  A peer that restarts (new `epoch_s`) starts over at once; a
clock step is re-locked from RELOCK_SAMPLES consecutive samples that disagree.

Why not Zenoh's HLC stamps: an HLC is a logical clock for ordering (it never goes back,
and is pushed forward by any faster clock it hears), not an offset estimate; it stamps
with the host's system clock, not the process clock the data are stamped with, and a
one-way stamp cannot separate offset from delay.

`ClockBook` holds one estimate per clock; `Decoder`s map every stamp of every message
from its sender's clock onto ours (`to_local`) before anything checks or ages it.  A
clock is a host's, not a process's: the book maps each sender to its host's clock
(`set_hosts`; transport.clock_sync estimates one offset per other host).  A sender without
an estimate is taken to share our clock (one host: nothing changes).
"""

from __future__ import annotations

import logging
import math
import threading
from collections import deque
from dataclasses import dataclass

from transport.fastbuild import build
from transport.messages import (
    ClockProbe,
    FollowerState,
    Header,
    Message,
    RunControl,
    TargetObservation,
)

log = logging.getLogger(__name__)
WINDOW_S = 8.0
DELAY_SLACK_S = 0.0005
MAX_DELAY_S = 2.0  # a round trip longer than this says nothing useful about the offset
RELOCK_SAMPLES = 3
RELOCK_MIN_S = 0.02  # a disagreement below this is delay noise, not a clock step


@dataclass(frozen=True)
class ClockSample:
    """One four-time exchange with a peer; `at_s` is our receive time (t4)."""

    offset_s: float
    delay_s: float
    at_s: float


def exchange_sample(t1_s: float, t2_s: float, t3_s: float, t4_s: float) -> ClockSample | None:
    """The sample of one exchange, or None if its times are impossible (a negative
    round trip: a clock stepped during it) or too slow to be useful."""
    delay = (t4_s - t1_s) - (t3_s - t2_s)
    if not all(math.isfinite(t) for t in (t1_s, t2_s, t3_s, t4_s)):
        return None
    if delay < 0.0 or delay > MAX_DELAY_S:
        return None
    return ClockSample(((t2_s - t1_s) + (t3_s - t4_s)) / 2.0, delay, t4_s)


class PeerClock:
    """The offset of one peer's clock from ours: windowed least-delay sample."""

    def __init__(self, window_s: float = WINDOW_S) -> None:
        self.window_s = window_s
        self.epoch_s: float | None = None
        self._samples: deque[ClockSample] = deque()
        self._offset_s: float | None = None
        self._disagree = 0
        self.resets = 0  # restarts and re-locks, for the status counters
        self.samples = 0

    @property
    def offset_s(self) -> float | None:
        """Peer clock minus ours; None before the first sample."""
        return self._offset_s

    def restart(self, epoch_s: float) -> None:
        """The peer is a new process (its epoch changed): forget the old clock."""
        if self.epoch_s is not None and epoch_s != self.epoch_s:
            self._samples.clear()
            self._offset_s = None
            self.resets += 1
        self.epoch_s = epoch_s

    def add(self, sample: ClockSample) -> float:
        self.samples += 1
        if self._offset_s is not None and self._steps(sample):
            log.warning("peer clock stepped by %.3f s: re-locked",
                        sample.offset_s - self._offset_s)
            self._samples = deque(list(self._samples)[-RELOCK_SAMPLES:])
            self.resets += 1
        self._samples.append(sample)
        horizon = sample.at_s - self.window_s
        while len(self._samples) > 1 and self._samples[0].at_s < horizon:
            self._samples.popleft()
        least = min(s.delay_s for s in self._samples)
        best = [s for s in self._samples if s.delay_s <= least + DELAY_SLACK_S][-1]
        self._offset_s = best.offset_s
        return best.offset_s

    def _steps(self, sample: ClockSample) -> bool:
        """RELOCK_SAMPLES samples in a row far from the estimate: a clock step."""
        assert self._offset_s is not None
        off = abs(sample.offset_s - self._offset_s)
        self._disagree = self._disagree + 1 if off > max(RELOCK_MIN_S, sample.delay_s) else 0
        if self._disagree >= RELOCK_SAMPLES:
            self._disagree = 0
            return True
        return False


_STAMP_FIELDS: dict[type, tuple[str, ...]] = {
    FollowerState: ("vehicle_stamp_s",),
    TargetObservation: ("observed_stamp_s",),
    RunControl: ("start_stamp_s",),
}


class ClockBook:
    """Offsets of every clock heard (by the id of the process that probes it: one per
    host); written by one clock-sync thread, read by the process loop (a float read is
    atomic).  `clock_of` maps a sender to the clock it stamps with (its host's)."""

    def __init__(self) -> None:
        self.peers: dict[str, PeerClock] = {}
        self.clock_of: dict[str, str] = {}
        self._lock = threading.Lock()

    def set_hosts(self, clock_of: dict[str, str]) -> None:
        """Sender id -> the id of the clock it stamps with (its host's router); senders
        on our own host map to our own clock, which is never in `peers`."""
        self.clock_of = dict(clock_of)

    def add(self, sender_id: str, epoch_s: float, sample: ClockSample) -> None:
        with self._lock:
            peer = self.peers.get(sender_id)
            if peer is None:
                peer = self.peers[sender_id] = PeerClock()
            peer.restart(epoch_s)
            peer.add(sample)

    def restart(self, sender_id: str, epoch_s: float) -> None:
        peer = self.peers.get(sender_id)
        if peer is not None:
            with self._lock:
                peer.restart(epoch_s)

    def offset_s(self, sender_id: str) -> float | None:
        peer = self.peers.get(self.clock_of.get(sender_id, sender_id))
        return None if peer is None else peer.offset_s

    def to_local(self, msg: Message) -> Message:
        """`msg` with every stamp moved from its sender's clock onto ours."""
        if isinstance(msg, ClockProbe):
            return msg  # the exchange works on the raw stamps
        offset = self.offset_s(msg.header.sender_id)
        if not offset:
            return msg
        # Every message a process receives comes through here: copied field dicts, not
        # dataclasses.replace (which runs the frozen __init__ twice; transport.fastbuild).
        head = msg.header
        fields = {**msg.__dict__, "header": build(Header, {
            "sender_id": head.sender_id, "seq": head.seq, "stamp_s": head.stamp_s - offset})}
        for f in _STAMP_FIELDS.get(type(msg), ()):
            fields[f] -= offset
        return build(type(msg), fields)

    def summary(self) -> dict[str, float]:
        """Offsets in ms by sender, for logs and status."""
        return {k: round(1e3 * p.offset_s, 3) for k, p in self.peers.items()
                if p.offset_s is not None}


PROCESS_BOOK = ClockBook()  # this process's peers; empty (identity) unless clock sync runs
