"""The recorder's intake: every sample on a known key recorded as it arrived.

Decoding each message into its dataclass and checking it to record it was most of the
recorder's CPU (issue 50), and nine in ten of ring64's messages are follower states, which
only the run's end needs whole.  So:
- Follower states and target observations ("deferred" keys) go into the MCAP as the JSON
  their wire array makes (mcap_log.wire_json: no dataclass, no checks), with their receive
  stamp; a payload that is no wire array of its key's type is not recorded.
- They wait packed here and are decoded, with every check of the `Decoder` and counted by
  it, a bounded batch at a time (`DECODE_BYTES`, a few seconds of ring64) and at the end of
  the run; the assembler gets them then.  One refused then is in the MCAP all the same:
  readers decode and check (deploy.recording.resume).
- The newest deferred sample of each key is kept for the live view and progress, and
  decoded, checked but not counted, at the view's rate (`peek`).
- The rest (truth, control, statuses: ~120 a second in ring64) the loop decodes at once
  and records only if accepted, as before.
Checks that need no decoding stay inline, counted by the decoder: a key that no message
type belongs on (`wrong_key`) or that is no process's of the scenario (`unknown_key`), a
payload over the codec's bound (`too_large`).  A sender's stamps are mapped onto our clock
(transport.peer_clock) with the offset of when the sample arrived.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Collection, Iterator
from dataclasses import dataclass

from deploy.recording.mcap_log import McapLog, wire_json
from transport.bus import Received
from transport.codec import MAX_PAYLOAD_BYTES
from transport.decoder import Decoder
from transport.message_checks import key_rule
from transport.messages import FollowerState, Message, TargetObservation
from transport.peer_clock import ClockBook

DEFERRED = (FollowerState, TargetObservation)
# Deferred samples are decoded once the oldest has waited DECODE_AGE_S or DECODE_BYTES of
# them wait (~4 s of ring64's states): the live counters are that late at most, the memory
# they take is bounded, and the run's end decodes at most that much (the launcher gives
# the recorder 120 s to write its outputs).
DECODE_AGE_S = 2.0
DECODE_BYTES = 4 * 1024 * 1024
_NS = 1_000_000_000
# receive stamp, clock offset (NaN: none), slot, payload length; then the payload
_HEAD = struct.Struct("<ddII")


@dataclass(frozen=True)
class Slot:
    """A known key: its message type, MCAP channel and whose clock stamps it."""

    id: int
    key: str
    cls: type
    channel: int
    deferred: bool
    owner: str
    follower: int | None  # the follower whose states these are


class _ArrivalClock(ClockBook):
    """One sample's offset, as it was when the sample arrived."""

    def __init__(self) -> None:
        super().__init__()
        self.offset: float | None = None

    def offset_s(self, sender_id: str) -> float | None:
        return self.offset


class Intake:
    """Records drained samples raw; hands back those to decode now (`take`)."""

    def __init__(self, mcap: McapLog, decoder: Decoder, senders: Collection[str],
                 n: int, decode_bytes: int = DECODE_BYTES,
                 decode_age_s: float = DECODE_AGE_S) -> None:
        self.mcap, self.decoder = mcap, decoder
        self.senders = frozenset(senders)
        self.decode_bytes, self.decode_age_s = decode_bytes, decode_age_s
        self._oldest_s = math.inf  # receive stamp of the oldest waiting
        self.arrivals = [0] * n  # follower states received, per follower (not yet checked)
        self.peak_bytes = 0
        self.deferred_decoded = 0
        self._slots: dict[str, Slot] = {}  # known keys only: bounded by the scenario
        self._by_id: list[Slot] = []
        self._newest: dict[str, Received] = {}
        self._pending = bytearray()
        self._arrival = _ArrivalClock()

    def _slot(self, key: str) -> Slot | None:
        rule = key_rule(key)
        if rule is None or rule.subject() not in self.senders:
            self.decoder.refuse("unknown_key", key)
            return None
        if rule.kind is None:
            self.decoder.refuse("wrong_key", key)
            return None
        follower = rule.index if rule.kind is FollowerState else None
        slot = Slot(len(self._by_id), key, rule.kind, self.mcap.channel(key, rule.kind),
                    rule.kind in DEFERRED, rule.owner, follower)
        self._slots[key] = slot
        self._by_id.append(slot)
        return slot

    def take(self, piece: list[Received]) -> list[tuple[Slot, Received]]:
        """Record `piece`'s deferred samples; the others, to be decoded now."""
        now: list[tuple[Slot, Received]] = []
        clocks = self.decoder.clocks
        for rec in piece:
            slot = self._slots.get(rec.key) or self._slot(rec.key)
            if slot is None:
                continue
            payload = rec.payload
            if len(payload) > MAX_PAYLOAD_BYTES:
                self.decoder.refuse("too_large", rec.key)
                continue
            if not slot.deferred:
                now.append((slot, rec))
                continue
            recv_s = rec.recv_stamp_s
            if not self._pending:
                self._oldest_s = recv_s
            recorded = wire_json(slot.cls, payload)
            if recorded is not None:
                data, stamp_ns, seq = recorded
                self.mcap.write_json(rec.key, slot.channel, data, int(recv_s * _NS), stamp_ns,
                                     seq)
            offset = clocks.offset_s(slot.owner) if clocks.peers else None
            self._pending += _HEAD.pack(recv_s, math.nan if offset is None else offset,
                                        slot.id, len(payload))
            self._pending += payload
            self._newest[rec.key] = rec
            if slot.follower is not None and 0 <= slot.follower < len(self.arrivals):
                self.arrivals[slot.follower] += 1
        self.peak_bytes = max(self.peak_bytes, len(self._pending))
        return now

    def due(self, now_s: float) -> bool:
        """Deferred samples have waited long enough, or enough of them wait."""
        return bool(self._pending) and (len(self._pending) >= self.decode_bytes
                                        or now_s - self._oldest_s >= self.decode_age_s)

    def decoded(self) -> Iterator[Message]:
        """Every deferred sample waiting, decoded and counted, oldest first (per key)."""
        data, self._pending = self._pending, bytearray()
        accept, arrival, slots = self.decoder.accept, self._arrival, self._by_id
        at = 0
        while at < len(data):
            recv_s, offset, sid, size = _HEAD.unpack_from(data, at)
            at += _HEAD.size
            arrival.offset = None if offset != offset else offset
            msg = accept(slots[sid].key, bytes(data[at:at + size]), recv_s, arrival)
            at += size
            self.deferred_decoded += 1
            if msg is not None:
                yield msg

    def peek(self) -> Iterator[tuple[Message, float]]:
        """The newest deferred sample of each key since the last peek, where it passes
        every check (not counted: it is, when its batch is decoded)."""
        newest, self._newest = self._newest, {}
        for rec in newest.values():
            msg, reason = self.decoder.screen(rec.key, rec.payload, rec.recv_stamp_s)
            if reason is None and msg is not None:
                yield msg, rec.recv_stamp_s
