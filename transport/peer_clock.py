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
follows drift closer still.

Probes are not signed by their sender: any holder of a router's certificate may publish
one under another router's name (routers relay every key).  So no probe moves an
estimate far: a sample that would move it by more than MAX_STEP_S is dropped and
counted, and at most one sample per peer per MIN_GAP_S is taken (routers probe every
0.25 s), so a forger drags a host's offset by at most MAX_STEP_S / MIN_GAP_S
(0.5 s/s), where an unbounded estimate jumped anywhere at once.  A real clock step (an
NTP step on a host) is followed in steps of MAX_STEP_S: each run of RELOCK_SAMPLES
samples far from the estimate on one side moves it by MAX_STEP_S towards them (a 0.5 s
step is re-locked after 10 runs, 30 probes, ~7.5 s).  A restarted router (new
`epoch_s`) runs on its host's clock as before: its old samples go, the estimate stays.

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
import time
from collections import Counter, deque
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
MAX_STEP_S = 0.05  # the most one probe may move a peer's offset estimate
MIN_GAP_S = 0.1  # of our clock between two samples of one peer (routers probe every 0.25 s)
LOG_EVERY_S = 10.0  # a dropped probe is logged at most this often per reason
DROP_REASONS = {
    "sender": "not a router of this swarm, or not on its own key",
    "times": "impossible or too slow four times (negative or > MAX_DELAY_S round trip)",
    "rate": f"closer than {MIN_GAP_S} s to the last one taken from that router",
    "step": "it would move the offset estimate by more than MAX_STEP_S",
}


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
    """The offset of one peer's clock from ours: windowed least-delay sample, moved by at
    most MAX_STEP_S per probe."""

    def __init__(self, window_s: float = WINDOW_S) -> None:
        self.window_s = window_s
        self.epoch_s: float | None = None
        self._samples: deque[ClockSample] = deque()
        self._offset_s: float | None = None
        self._side = 0  # sign of the current run of far samples (a step?), and its length
        self._run = 0
        self._last_at_s = -math.inf
        self.resets = 0  # restarts and re-lock steps, for the status counters
        self.samples = 0

    @property
    def offset_s(self) -> float | None:
        """Peer clock minus ours; None before the first sample."""
        return self._offset_s

    def restart(self, epoch_s: float) -> None:
        """The peer is a new process (its epoch changed): its old samples go; the estimate
        stays (a router restarts on its host's clock) and bounds the new samples."""
        if self.epoch_s is not None and epoch_s != self.epoch_s:
            self._samples.clear()
            self.resets += 1
        self.epoch_s = epoch_s

    def add(self, sample: ClockSample) -> str | None:
        """Take `sample` into the estimate; or drop it and say why: "rate" (within
        MIN_GAP_S of the last one taken) or "step" (it would move the estimate by more
        than MAX_STEP_S)."""
        if sample.at_s - self._last_at_s < MIN_GAP_S:
            return "rate"
        self._last_at_s = sample.at_s
        stepped = self._offset_s is not None and self._steps(sample)
        if stepped:  # the old samples are of the clock before the step
            self._samples.clear()
            self.resets += 1
        window = deque(self._samples)
        window.append(sample)
        horizon = sample.at_s - self.window_s
        while len(window) > 1 and window[0].at_s < horizon:
            window.popleft()
        least = min(s.delay_s for s in window)
        best = [s for s in window if s.delay_s <= least + DELAY_SLACK_S][-1].offset_s
        if self._offset_s is not None and abs(best - self._offset_s) > MAX_STEP_S:
            if stepped:
                log.warning("peer clock stepped by %+.3f s: following it by %.3f s",
                            best - self._offset_s, MAX_STEP_S)
                self._offset_s += math.copysign(MAX_STEP_S, best - self._offset_s)
            return "step"
        self.samples += 1
        self._samples, self._offset_s = window, best
        return None

    def _steps(self, sample: ClockSample) -> bool:
        """RELOCK_SAMPLES samples in a row far from the estimate, on one side: a step."""
        assert self._offset_s is not None
        off = sample.offset_s - self._offset_s
        if abs(off) <= max(RELOCK_MIN_S, sample.delay_s):
            self._run = 0
            return False
        side = 1 if off > 0.0 else -1
        self._run = self._run + 1 if side == self._side else 1
        self._side = side
        if self._run < RELOCK_SAMPLES:
            return False
        self._run = 0
        return True


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
        self.dropped: Counter[str] = Counter()  # why probes were dropped (DROP_REASONS)
        self._logged_s: dict[str, float] = {}
        self._lock = threading.Lock()

    def set_hosts(self, clock_of: dict[str, str]) -> None:
        """Sender id -> the id of the clock it stamps with (its host's router); senders
        on our own host map to our own clock, which is never in `peers`."""
        self.clock_of = dict(clock_of)

    def add(self, sender_id: str, epoch_s: float, sample: ClockSample) -> bool:
        """A sample of clock `sender_id` (a known router: the caller checked); False if
        it was dropped (counted)."""
        with self._lock:
            peer = self.peers.get(sender_id)
            if peer is None:
                peer = self.peers[sender_id] = PeerClock()
            peer.restart(epoch_s)
            why = peer.add(sample)
        if why is not None:
            self.drop(why, sender_id)
        return why is None

    def drop(self, why: str, sender: str) -> None:
        """Count a dropped probe (`why` one of DROP_REASONS); logged once per LOG_EVERY_S
        per reason, with the sender it claimed."""
        self.dropped[why] += 1
        now = time.monotonic()
        if now - self._logged_s.get(why, -math.inf) >= LOG_EVERY_S:
            self._logged_s[why] = now
            log.warning("clock probe from %r dropped: %s (%d so far)", sender[:40],
                        DROP_REASONS[why], self.dropped[why])

    def counters(self) -> dict[str, int]:
        """The status counters of dropped probes (`clock_probes_dropped_<why>`), non-zero."""
        return {f"clock_probes_dropped_{why}": n for why, n in self.dropped.items() if n}

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
