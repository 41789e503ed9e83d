"""Bounded work per tick for a MAVLink receiver: what is read, screened and parsed.

A receiver that reads until its socket is empty is the flooder's to stall: one 64 KB
datagram of badly signed frames took ~10 ms to parse and reject, so a hundred of them a
second stopped a follower's loop.  Each tick a receiver (the agent's adapter, each of the
simulator's vehicles) now takes at most `RxBudget.datagrams` datagrams and parses at most
`RxBudget.parse_bytes` bytes; what is left waits in the socket for the next tick (the
kernel drops what overflows its buffer).  With signing on, each datagram is first judged
by its first frame alone (`SignatureVerifier.screen`, one hash): a refused one is dropped
unparsed and counted under its reason (signing_rejected_<reason>), so a flood of badly
signed datagrams costs a read and a hash each.  A datagram that would take the tick past
its parse budget is kept whole for the next tick (`RxGate.new_tick` hands it back), so a
burst of good datagrams is delayed, never lost; only one larger than a whole tick's budget
is cut there, its tail dropped and counted (`mav_flood_drops`, `mav_flood_bytes`).
A datagram whose first frame passes only because its type may travel unsigned (an unsigned
HEARTBEAT: 8 or 12 bytes, no CRC checked by the screen) is cut after that frame
(`unsigned_tails`): the prefix vouches for itself alone, not for the kilobytes behind it,
which would otherwise all be parsed (ground stations and SDKs send one message a datagram).
Refusals are logged at most once per LOG_EVERY_S per receiver, with their count, reasons
and the last sender.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

from agents.mavlink.signing import IFLAG_SIGNED, STX_V1, STX_V2, SignatureVerifier

log = logging.getLogger(__name__)
LOG_EVERY_S = 10.0
Addr = tuple[str, int]
Carried = tuple[bytes, Addr | None, float]  # a datagram, its sender and arrival stamp


@dataclass(frozen=True)
class RxBudget:
    """What one receiver takes per tick: datagrams read, and bytes handed to the parser."""

    datagrams: int
    parse_bytes: int


# Measured here: a 64 KB datagram of signed frames takes 9.2 ms to parse and verify, its
# screen 2.6 us (3.2 us for one small frame).  So a tick spends at most ~2.3 ms parsing
# and ~0.8 ms screening.  An agent reads one vehicle's telemetry: a datagram or a few per
# tick, under 2 KB.
ADAPTER_BUDGET = RxBudget(datagrams=256, parse_bytes=16 * 1024)
# A simulated vehicle hears its agent and ground stations: a few datagrams a tick.
VEHICLE_BUDGET = RxBudget(datagrams=32, parse_bytes=8 * 1024)


class RefusalLog:
    """Refused datagrams of one receiver, logged at most once per `every_s`."""

    def __init__(self, name: str, every_s: float = LOG_EVERY_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.name = name
        self.every_s = every_s
        self.clock = clock
        self.pending: Counter[str] = Counter()
        self.last_sender: Addr | None = None
        self._last_log_s = -float("inf")

    def note(self, reason: str, sender: Addr | None) -> None:
        self.pending[reason] += 1
        self.last_sender = sender
        now = self.clock()
        if now - self._last_log_s < self.every_s:
            return
        self._last_log_s = now
        why = ", ".join(f"{k} {v}" for k, v in sorted(self.pending.items()))
        sender_text = "?" if sender is None else f"{sender[0]}:{sender[1]}"
        log.warning("%s: refused %d datagram(s) since the last report (%s), the last from %s",
                    self.name, sum(self.pending.values()), why, sender_text)
        self.pending.clear()


class RxGate:
    """One receiver's budget: `new_tick()` each tick, `open` while it may read one more
    datagram, `admit(data, sender)` the part of a datagram to parse (None: refused)."""

    def __init__(self, name: str, budget: RxBudget, counters: Counter[str],
                 verifier: SignatureVerifier | None = None) -> None:
        self.budget = budget
        self.counters = counters
        self.verifier = verifier
        self.refusals = RefusalLog(name)
        self.datagrams = 0
        self.parsed_bytes = 0
        self.carried: Carried | None = None

    def new_tick(self) -> Carried | None:
        """A fresh budget; the datagram the last tick had no room for, if any, already
        charged to this one: the receiver parses it first."""
        carried, self.carried = self.carried, None
        self.datagrams = 0 if carried is None else 1
        self.parsed_bytes = 0 if carried is None else len(carried[0])
        return carried

    @property
    def open(self) -> bool:
        return (self.datagrams < self.budget.datagrams
                and self.parsed_bytes < self.budget.parse_bytes)

    def admit(self, data: bytes, sender: Addr | None, stamp: float = 0.0) -> bytes | None:
        """What of `data` to parse now: None when its first frame is refused (counted under
        its reason) or when the tick has no room left for it (kept for the next tick, with
        `stamp`); else `data`, cut at the parse budget if it alone exceeds it (counted)."""
        if self.verifier is not None:
            reason = self.verifier.screen(data)
            if reason is not None:
                self.refuse(reason, sender)
                return None
            head = unsigned_head(data)
            if head is not None and head < len(data):
                self.counters["unsigned_tails"] += 1
                data = data[:head]
        self.datagrams += 1
        room = self.budget.parse_bytes - self.parsed_bytes
        if len(data) > room and self.parsed_bytes > 0:
            self.carried = (data, sender, stamp)
            self.parsed_bytes = self.budget.parse_bytes  # the gate closes for this tick
            return None
        if len(data) > room:
            self.counters["mav_flood_drops"] += 1
            self.counters["mav_flood_bytes"] += len(data) - max(0, room)
            self.refusals.note("over budget", sender)
            data = data[:max(0, room)]
        self.parsed_bytes += len(data)
        return data


    def refuse(self, reason: str, sender: Addr | None) -> None:
        """A datagram whose first frame the verifier refused (counted there as
        rejected_<reason>): counted here, logged, dropped unparsed."""
        self.datagrams += 1
        assert self.verifier is not None
        self.verifier.count_rejection(reason, self.counters)
        self.refusals.note(reason, sender)

    def fits(self, size: int) -> bool:
        """Whether a datagram of `size` bytes is parsed whole this tick (`take` it then)."""
        return size <= self.budget.parse_bytes - self.parsed_bytes

    def take(self, size: int) -> None:
        """Charge a datagram that `fits`, read past the screen by agents.mavlink.fast_rx."""
        self.datagrams += 1
        self.parsed_bytes += size


def unsigned_head(data: bytes) -> int | None:
    """The length of the datagram's first frame if that frame is unsigned (MAVLink 1, or 2
    without the signed flag), else None; `data` passed the screen, so the frame is whole."""
    if len(data) < 2:
        return None
    if data[0] == STX_V1:
        return 8 + data[1]
    if data[0] == STX_V2 and len(data) > 2 and not data[2] & IFLAG_SIGNED:
        return 12 + data[1]
    return None
