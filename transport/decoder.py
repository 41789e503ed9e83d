"""Turn drained samples into messages without ever raising.

A `Decoder` belongs to one process loop.  Every payload that fails to decode
is dropped and counted under its `CodecError.reason`; a message whose type is
not expected on that subscription, or that does not belong on its key (its type, the
index it carries: transport.message_checks.key_reason), is dropped too, and so, given `limits`,
is an implausible one (transport.message_checks), and, given `law_fields`, a FollowerState whose
law fields are not the declared ones (transport.law_fields: `rejected_law_<why>`).
Given `senders` -- the scenario's processes (transport.access.sender_ids) -- a message
from any other sender is dropped (`unknown_sender`), and so is one on a key that is not
the swarm's or names another process (`unknown_key`): every table kept per sender or key
(its streams, gaps, the links of transport.link_stats, a recorder's channels) is then
bounded by the scenario, whatever names arrive.
Every drop is also counted per kind of key (`statuses_rejected`, `observations_rejected`,
...) and, where the key names a known process, per sender (the key's owner: with access
control on, the process that put it, whatever it claims), and logged at most once every
ten seconds per reason (transport.ratelog).
Per stream -- (sender id, key), since a sender numbers each
key it publishes on separately -- it counts sequence gaps (messages never seen) and
stale messages (sequence number not above the last one: duplicated or
reordered) -- stale messages are still delivered, flagged, since only the
consumer knows whether "latest by seq" matters.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass

from errors import CodecError
from transport.bus import Received, Subscription
from transport.codec import decode
from transport.fastbuild import build
from transport.law_fields import FieldSpec
from transport.law_fields import reason as law_reason
from transport.message_checks import Limits, check, key_reason, key_rule
from transport.messages import (
    ClockProbe,
    FollowerState,
    Message,
    ProcessStatus,
    RunControl,
    TargetObservation,
    TruthSnapshot,
)
from transport.peer_clock import PROCESS_BOOK, ClockBook
from transport.ratelog import RateLimitedLog

log = logging.getLogger("enclose.bus")
# Counter names of the drops per kind of message (`<kind>_rejected`).
KIND_NAMES: dict[type | None, str] = {
    FollowerState: "states", TargetObservation: "observations", ProcessStatus: "statuses",
    TruthSnapshot: "truth", RunControl: "control", ClockProbe: "clock"}
TOP_SENDERS = 3  # senders named in the counters (`rejected_from_<sender>`), most first


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


class _Claims:
    """Who a dropped message says it is from (and, for a status, for): formatted only if
    logged."""

    def __init__(self, msg: Message | None) -> None:
        self.msg = msg

    def __str__(self) -> str:
        msg = self.msg
        if msg is None:
            return ""
        text = f"; it claims to be from {msg.header.sender_id[:64]!r}"
        if isinstance(msg, ProcessStatus):
            text += f" for {f'{msg.role[:64]}-{msg.index}'!r}"
        return text


class Decoder:
    """Decodes, validates and counts; `expect` limits the accepted message types."""

    def __init__(self, expect: tuple[type, ...] | None = None,
                 limits: Limits | None = None, clocks: ClockBook = PROCESS_BOOK,
                 senders: Collection[str] | None = None,
                 law_fields: Mapping[str, FieldSpec] | None = None) -> None:
        self.expect = expect
        self.law_fields = law_fields
        self.clocks = clocks  # stamps are mapped onto our clock (transport.peer_clock)
        # with limits, implausible messages are dropped (transport.message_checks)
        self.limits = limits
        self.senders = None if senders is None else frozenset(senders)
        self.dropped: Counter[str] = Counter()
        self.rejected: Counter[str] = Counter()  # per kind of key (KIND_NAMES)
        self.rejected_from: Counter[str] = Counter()  # per known sender
        self.log = RateLimitedLog(log)
        self.accepted = 0
        self.last_stale = False  # of the last message accepted
        self.gaps: Counter[str] = Counter()  # per sender id, over its streams
        self.stale: Counter[str] = Counter()
        self._last_seq: dict[tuple[str, str], int] = {}

    def forget(self, key: str) -> None:
        """The sender on `key` is gone: a new process there numbers its messages from 0
        again, which is neither a gap nor stale."""
        for stream in [s for s in self._last_seq if s[1] == key]:
            del self._last_seq[stream]

    def decode(self, rec: Received) -> Inbound | None:
        msg = self.accept(rec.key, rec.payload, rec.recv_stamp_s)
        if msg is None:
            return None
        return build(Inbound, {"message": msg, "received": rec, "stale": self.last_stale})

    def accept(self, key: str, payload: bytes, recv_stamp_s: float,
               clocks: ClockBook | None = None) -> Message | None:
        """`decode` without the `Inbound` (staleness in `last_stale`), the stamps mapped
        with `clocks` (None: ours now)."""
        msg, reason = self.screen(key, payload, recv_stamp_s, clocks)
        if reason is not None:
            self._drop(reason, key, msg)
            return None
        assert msg is not None  # accepted
        self.accepted += 1
        self.last_stale = self._track(msg.header.sender_id, key, msg.header.seq)
        return msg

    def screen(self, key: str, payload: bytes, recv_stamp_s: float,
               clocks: ClockBook | None = None) -> tuple[Message | None, str | None]:
        """Every check of `decode`, nothing counted: (the message on our clock, None), or
        (what it claims to be, if it decoded, and the reason it is refused).  `clocks`:
        the stamps' mapping to use instead of ours now (one taken when it arrived)."""
        try:
            msg = decode(payload)
        except CodecError as exc:
            return None, exc.reason
        if self.expect is not None and not isinstance(msg, self.expect):
            return msg, "unexpected_type"
        reason = key_reason(msg, key) or self._sender_reason(msg, key)
        if reason is not None:
            return msg, reason
        if clocks is not None:
            msg = clocks.to_local(msg)
        elif self.clocks.peers:  # one host: no clock to map from, and no call per message
            msg = self.clocks.to_local(msg)
        if self.limits is not None:
            reason = check(msg, key, recv_stamp_s, self.limits)
            if reason is None and self.law_fields is not None and type(msg) is FollowerState \
                    and msg.law:
                reason = law_reason(msg.law, self.law_fields)
            if reason is not None:
                return msg, f"rejected_{reason}"
        return msg, None

    def refuse(self, reason: str, key: str) -> None:
        """Count a refusal decided before decoding (the key alone, the size)."""
        self._drop(reason, key, None)

    def _sender_reason(self, msg: Message, key: str) -> str | None:
        """With `senders`: the sender, and the process the key is about, must be known."""
        if self.senders is None:
            return None
        if msg.header.sender_id not in self.senders:
            return "unknown_sender"
        rule = key_rule(key)
        return "unknown_key" if rule is None or rule.subject() not in self.senders else None

    def _drop(self, reason: str, key: str, msg: Message | None) -> None:
        """Count a refusal by reason, by kind and by the key's owner; log it, rate-limited."""
        self.dropped[reason] += 1
        rule = key_rule(key)
        kind = rule.kind if rule is not None else None if msg is None else type(msg)
        self.rejected[KIND_NAMES.get(kind, "other")] += 1
        owner = None if rule is None else rule.owner
        if owner is not None and self.senders is not None and owner in self.senders:
            self.rejected_from[owner] += 1
        self.log.warning(reason, "dropped a message on %r (%s), the key of %s%s", key[:160],
                         reason, owner or "no known process", _Claims(msg))

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
        """Flat counters for a ProcessStatus: accepted, drop_<reason>, seq_gap, seq_stale,
        <kind>_rejected and rejected_from_<sender> (the TOP_SENDERS most rejected)."""
        out = {"accepted": self.accepted, "seq_gap": sum(self.gaps.values()),
               "seq_stale": sum(self.stale.values())}
        out.update({f"drop_{reason}": n for reason, n in sorted(self.dropped.items())})
        out.update({f"{kind}_rejected": n for kind, n in sorted(self.rejected.items())})
        out.update({f"rejected_from_{sender}": n
                    for sender, n in self.rejected_from.most_common(TOP_SENDERS)})
        return out
