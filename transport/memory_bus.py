"""In-memory bus for unit tests: same interface and semantics as the Zenoh bus.

A `MemoryHub` plays the network; each in-process "agent" opens its own
`MemoryBus` on the hub.  Delivery is synchronous and deterministic: `put`
appends to the queue of every matching subscription (in subscription order),
and `drain()` returns what is queued.  Like Zenoh, the publisher's clock at
`put` becomes the sample's HLC stamp, and the receive stamp is taken at drain.
Closing a bus withdraws its liveliness tokens, as a process exit does.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections import deque

from errors import TransportError
from transport.bus import (
    DEFAULT_CAPACITY,
    AliveEvent,
    BusBase,
    Clock,
    Congestion,
    Received,
    apply_alive,
)
from transport.key_exprs import key_matches, validate_concrete


class MemoryHub:
    """The shared "network" of several MemoryBus sessions."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.subscriptions: list[MemorySubscription] = []
        self.watches: list[MemoryAliveWatch] = []
        self.tokens: dict[str, int] = {}
        self._ids = itertools.count()

    def next_id(self) -> int:
        return next(self._ids)

    def deliver(self, key: str, payload: bytes, stamp_s: float, source: str) -> None:
        with self.lock:
            for sub in self.subscriptions:
                if key_matches(sub.key_expr, key):
                    sub.queue.append((key, payload, stamp_s, source))

    def set_token(self, key: str, delta: int) -> None:
        with self.lock:
            before = self.tokens.get(key, 0)
            after = before + delta
            self.tokens[key] = after
            if (before == 0) != (after == 0):
                for watch in self.watches:
                    if key_matches(watch.key_expr, key):
                        watch.events.append(AliveEvent(key, after > 0))

    def alive_keys(self, key_expr: str) -> list[str]:
        with self.lock:
            return sorted(k for k, n in self.tokens.items() if n > 0 and key_matches(key_expr, k))


class MemorySubscription:
    def __init__(self, bus: MemoryBus, key_expr: str, capacity: int) -> None:
        self.key_expr = key_expr
        self._bus = bus
        self.queue: deque[tuple[str, bytes, float, str]] = deque(maxlen=capacity)

    def drain(self, max_items: int | None = None) -> list[Received]:
        now = self._bus.now_s()
        out: list[Received] = []
        with self._bus.hub.lock:
            while self.queue and (max_items is None or len(out) < max_items):
                key, payload, stamp_s, source = self.queue.popleft()
                out.append(Received(key, payload, now, stamp_s, source))
        return out

    def close(self) -> None:
        with self._bus.hub.lock:
            if self in self._bus.hub.subscriptions:
                self._bus.hub.subscriptions.remove(self)


class MemoryPublisher:
    def __init__(self, bus: MemoryBus, key: str, congestion: Congestion) -> None:
        self.key = validate_concrete(key)
        self.congestion = congestion
        self._bus = bus
        self._closed = False

    def put(self, payload: bytes) -> None:
        if self._closed or self._bus.closed:
            raise TransportError(f"publisher {self.key} is closed")
        self._bus.hub.deliver(self.key, bytes(payload), self._bus.now_s(), self._bus.name)

    def matched(self) -> bool:
        with self._bus.hub.lock:
            return any(key_matches(s.key_expr, self.key) for s in self._bus.hub.subscriptions)

    def close(self) -> None:
        self._closed = True


class MemoryToken:
    def __init__(self, hub: MemoryHub, key: str) -> None:
        self.key = validate_concrete(key)
        self._hub = hub
        self._closed = False
        hub.set_token(self.key, +1)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._hub.set_token(self.key, -1)


class MemoryAliveWatch:
    def __init__(self, hub: MemoryHub, key_expr: str) -> None:
        self.key_expr = key_expr
        self._hub = hub
        self._alive: set[str] = set()
        with hub.lock:
            # Like Zenoh's `history=True`: tokens already alive arrive as events.
            self.events: deque[AliveEvent] = deque(
                AliveEvent(k, True) for k in hub.alive_keys(key_expr)
            )
            hub.watches.append(self)

    def drain_events(self) -> list[AliveEvent]:
        with self._hub.lock:
            events = list(self.events)
            self.events.clear()
        for ev in events:
            apply_alive(self._alive, ev)
        return events

    def poll(self) -> frozenset[str]:
        self.drain_events()
        return frozenset(self._alive)

    def close(self) -> None:
        with self._hub.lock:
            if self in self._hub.watches:
                self._hub.watches.remove(self)


class MemoryBus(BusBase):
    """One session on a MemoryHub; `name` is what HLC `source` reports."""

    def __init__(self, hub: MemoryHub, name: str = "", clock: Clock = time.time) -> None:
        super().__init__()
        self.hub = hub
        self.name = name or f"mem{hub.next_id()}"
        self.closed = False
        self._clock = clock
        self._owned: list[MemorySubscription | MemoryToken | MemoryAliveWatch] = []

    def now_s(self) -> float:
        return self._clock()

    def _check_open(self) -> None:
        if self.closed:
            raise TransportError(f"bus {self.name} is closed")

    def declare_publisher(
        self, key: str, congestion: Congestion = Congestion.DROP
    ) -> MemoryPublisher:
        self._check_open()
        return MemoryPublisher(self, key, congestion)

    def subscribe(self, key_expr: str, capacity: int = DEFAULT_CAPACITY,
                  stamp_arrival: bool = False, hlc: bool = True) -> MemorySubscription:
        # Delivery is immediate here: a sample arrives when drained (arrival_s None).
        self._check_open()
        sub = MemorySubscription(self, key_expr, capacity)
        with self.hub.lock:
            self.hub.subscriptions.append(sub)
        self._owned.append(sub)
        return sub

    def declare_token(self, key: str) -> MemoryToken:
        self._check_open()
        token = MemoryToken(self.hub, key)
        self._owned.append(token)
        return token

    def watch_alive(self, key_expr: str) -> MemoryAliveWatch:
        self._check_open()
        watch = MemoryAliveWatch(self.hub, key_expr)
        self._owned.append(watch)
        return watch

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        for obj in reversed(self._owned):
            obj.close()
        self._owned.clear()
        self._publishers.clear()
