"""Turn drained samples into messages without ever raising.

A `Decoder` belongs to one process loop.  Every payload that fails to decode
is dropped and counted under its `CodecError.reason`; a message whose type is
not expected on that subscription, or whose index disagrees with its key, is
dropped too, and so, given `limits`, is an implausible one (transport.checks).
Per stream -- (sender id, key), since a sender numbers each
key it publishes on separately -- it counts sequence gaps (messages never seen) and
stale messages (sequence number not above the last one: duplicated or
reordered) -- stale messages are still delivered, flagged, since only the
consumer knows whether "latest by seq" matters.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass

from transport.bus import Received, Subscription
from transport.checks import Limits, check
from transport.codec import decode
from transport.errors import CodecError
from transport.fastbuild import build
from transport.keys import parse_key
from transport.messages import FollowerState, Message, TargetObservation
from transport.peer_clock import PROCESS_BOOK, ClockBook


@dataclass(frozen=True)
class Inbound:
    """A decoded message with its bus metadata."""

    message: Message
    received: Received
    stale: bool = False  # seq not above the sender's last seen seq

    @property
    def latency_s(self) -> float:
        """Receive stamp minus sender stamp (meaningful when the clocks agree)."""
        return self.received.recv_stamp_s - self.message.header.stamp_s


def _key_index_ok(msg: Message, key: str) -> bool:
    info = parse_key(key)
    if info is None or info.index is None:
        return True
    if isinstance(msg, FollowerState) and info.kind == "follower":
        return msg.index == info.index
    if isinstance(msg, TargetObservation) and info.kind == "sensor":
        return msg.observer_index == info.index
    return True


class Decoder:
    """Decodes, validates and counts; `expect` limits the accepted message types."""

    def __init__(self, expect: tuple[type, ...] | None = None,
                 limits: Limits | None = None, clocks: ClockBook = PROCESS_BOOK) -> None:
        self.expect = expect
        self.clocks = clocks  # stamps are mapped onto our clock (transport.peer_clock)
        self.limits = limits  # with limits, implausible messages are dropped (transport.checks)
        self.dropped: Counter[str] = Counter()
        self.accepted = 0
        self.gaps: Counter[str] = Counter()  # per sender id, over its streams
        self.stale: Counter[str] = Counter()
        self._last_seq: dict[tuple[str, str], int] = {}

    def forget(self, key: str) -> None:
        """The sender on `key` is gone: a new process there numbers its messages from 0
        again, which is neither a gap nor stale."""
        for stream in [s for s in self._last_seq if s[1] == key]:
            del self._last_seq[stream]

    def decode(self, rec: Received) -> Inbound | None:
        try:
            msg = decode(rec.payload)
        except CodecError as exc:
            self.dropped[exc.reason] += 1
            return None
        if self.expect is not None and not isinstance(msg, self.expect):
            self.dropped["unexpected_type"] += 1
            return None
        if not _key_index_ok(msg, rec.key):
            self.dropped["key_mismatch"] += 1
            return None
        msg = self.clocks.to_local(msg)
        if self.limits is not None:
            reason = check(msg, rec.key, rec.recv_stamp_s, self.limits)
            if reason is not None:
                self.dropped[f"rejected_{reason}"] += 1
                return None
        self.accepted += 1
        stale = self._track(msg.header.sender_id, rec.key, msg.header.seq)
        return build(Inbound, {"message": msg, "received": rec, "stale": stale})

    def _track(self, sender: str, key: str, seq: int) -> bool:
        last = self._last_seq.get((sender, key))
        if last is not None and seq <= last:
            self.stale[sender] += 1
            return True
        if last is not None and seq > last + 1:
            self.gaps[sender] += seq - last - 1
        self._last_seq[(sender, key)] = seq
        return False

    def decode_all(self, received: Iterable[Received]) -> list[Inbound]:
        out = []
        for rec in received:
            inbound = self.decode(rec)
            if inbound is not None:
                out.append(inbound)
        return out

    def drain(self, sub: Subscription, max_items: int | None = None) -> list[Inbound]:
        return self.decode_all(sub.drain(max_items))

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())

    def counters(self) -> dict[str, int]:
        """Flat counters for a ProcessStatus: accepted, drop_<reason>, seq_gap, seq_stale."""
        out = {"accepted": self.accepted, "seq_gap": sum(self.gaps.values()),
               "seq_stale": sum(self.stale.values())}
        out.update({f"drop_{reason}": n for reason, n in sorted(self.dropped.items())})
        return out
