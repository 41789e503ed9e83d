"""The clock exchange of one process: probes out, probes in, offsets into a ClockBook.

A small thread (not the process loop: the loop may run at 10-50 Hz or block in start-up,
and a probe's receive time must be taken when it arrives, not a tick later) polls the
probe subscription every POLL_S and publishes a probe every PERIOD_S on
`<swarm>/clock/<role>/<index>`.  Each probe echoes the newest probe heard from every peer
(its stamp, our receive time), so every pair of processes gets a four-time NTP sample from
each probe (transport.peer_clock).  Only the bus interface is used: publisher `put` and
subscription `drain` are safe from another thread in Zenoh; nothing else is shared but
the book.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from agents.errors import CodecError, TransportError
from transport.bus import Bus
from transport.codec import decode, encode
from transport.keys import SwarmKeys, parse_key
from transport.messages import ClockProbe, Stamper
from transport.peer_clock import PROCESS_BOOK, ClockBook, exchange_sample

log = logging.getLogger(__name__)
PERIOD_S = 0.25
POLL_S = 0.01  # a probe waits at most this long to be stamped; the least-delay filter
# keeps the samples that waited least (2 ms polls cost ~500 wake-ups/s per process)
QUEUE = 256


class ClockExchange:
    """The pure part: what to send, and what a received probe teaches (injected clock)."""

    def __init__(self, sender_id: str, clock: Callable[[], float], book: ClockBook) -> None:
        self.sender_id, self.clock, self.book = sender_id, clock, book
        self.epoch_s = clock()
        self.stamper = Stamper(sender_id, clock)
        self.heard: dict[str, tuple[float, float]] = {}  # peer -> (its stamp t1, our t2)
        self.rejected = 0

    def probe(self) -> ClockProbe:
        echoes = tuple((peer, t1, t2) for peer, (t1, t2) in sorted(self.heard.items()))
        return ClockProbe(self.stamper.header(), self.epoch_s, echoes)

    def receive(self, probe: ClockProbe, t4_s: float) -> None:
        peer = probe.header.sender_id
        if peer == self.sender_id:
            return
        self.heard[peer] = (probe.header.stamp_s, t4_s)
        self.book.restart(peer, probe.epoch_s)
        for echoed, t1, t2 in probe.echoes:
            if echoed != self.sender_id:
                continue
            sample = exchange_sample(t1, t2, probe.header.stamp_s, t4_s)
            if sample is None:
                self.rejected += 1
            else:
                self.book.add(peer, probe.epoch_s, sample)

    def forget(self, peer: str) -> None:
        self.heard.pop(peer, None)


class ClockSync:
    """Runs a ClockExchange on a bus in a thread; `close()` before the bus closes."""

    def __init__(self, bus: Bus, keys: SwarmKeys, sender_id: str,
                 book: ClockBook = PROCESS_BOOK, period_s: float = PERIOD_S) -> None:
        role, _, index = sender_id.rpartition("-")
        self.exchange = ClockExchange(sender_id, bus.now_s, book)
        self.period_s = period_s
        self._bus = bus
        self._out = bus.declare_publisher(keys.clock(role, int(index)))
        self._sub = bus.subscribe(keys.all_clock(), QUEUE)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="clock-sync", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        next_s = 0.0
        while not self._stop.is_set():
            try:
                for rec in self._sub.drain():
                    self._receive(rec.key, rec.payload, rec.recv_stamp_s)
                now = self._bus.now_s()
                if now >= next_s:
                    next_s = now + self.period_s
                    self._out.put(encode(self.exchange.probe()))
            except TransportError as exc:  # closing, or a link down: try again next poll
                log.debug("clock sync: %s", exc)
            self._stop.wait(POLL_S)

    def _receive(self, key: str, payload: bytes, t4_s: float) -> None:
        try:
            msg = decode(payload)
        except CodecError:
            self.exchange.rejected += 1
            return
        info = parse_key(key)
        owner = None if info is None else f"{info.role}-{info.index}"
        if isinstance(msg, ClockProbe) and msg.header.sender_id == owner:
            self.exchange.receive(msg, t4_s)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
