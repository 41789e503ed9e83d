"""The bus interface every process talks through, and its plain data types.

Design:
- Pull, never push.  A subscription is a bounded queue filled by the transport's
  own threads and drained by the process's single loop with `drain()`, which
  never blocks.  Transport callbacks never touch agent state.
- Bounded queues keep the newest samples: when a loop stalls, the oldest
  samples are dropped (and later show up as sequence gaps in `codec.Decoder`).
- Liveliness: `declare_token(key)` says "this process is up" for as long as
  the token (or the process) lives; `watch_alive(key_expr)` tracks the set of
  live tokens, so a launcher waits for "all linked" without sleeping.
- Impairment sits on the receiving side: a wrapper implementing `Bus` can hold,
  drop, duplicate or reorder what `drain()` returns, per link, because every key
  names its sender (`keys.parse_key`) and every `Received` carries its receive
  stamp.  Nothing in the agent changes.

Times are seconds from the bus clock (default `time.time`, so stamps from
processes on one host, and Zenoh HLC stamps, are comparable).
"""

from __future__ import annotations

import enum
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Protocol, Self

from errors import TransportError

Clock = Callable[[], float]

DEFAULT_CAPACITY = 1024
# Keys a watch keeps as alive.  Tokens are declared by whoever may on their keys: a swarm
# has a few hundred at most, and beyond this a token is still an event but not remembered.
MAX_ALIVE_KEYS = 4096


class Congestion(enum.Enum):
    """What a publisher does when a link's send queue is full.

    DROP is the default: real-time data (states, estimates, truth, sensing, statuses) is
    replaced by the next tick's, and a consumer that stops reading (a slow or hostile
    subscriber on the swarm's keys) must not hold a publisher's tick: with BLOCK a put
    waits for that consumer's queue, up to Zenoh's close timeout (5 s for peers).  DROP
    loses a sample only on a link whose queue is full; on loopback TCP at our rates none
    is (BENCHMARKS.md).  BLOCK is for words sent once that must not be lost: `publish`
    (the run-control words, a process's state changes).
    """

    BLOCK = "block"  # wait: no loss on TCP; a consumer that stops reading stalls the put
    DROP = "drop"  # drop the sample on a full link: never stalls the sender's loop


@dataclass(frozen=True)
class Received:
    """One sample taken off the bus."""

    key: str
    payload: bytes
    recv_stamp_s: float  # receiver's bus clock when the sample was drained
    hlc_stamp_s: float | None = None  # Zenoh HLC stamp of the publisher, if any
    hlc_source: str | None = None  # id of the session that stamped it
    # Receiver's bus clock when the sample reached this process (not when drained), if the
    # bus stamps arrivals (ZenohConfig.arrival_stamps): one-way latency = arrival - HLC.
    arrival_s: float | None = None


@dataclass(frozen=True)
class AliveEvent:
    """A liveliness token appeared (`alive` True) or vanished."""

    key: str
    alive: bool


class Subscription(Protocol):
    key_expr: str

    def drain(self, max_items: int | None = None) -> list[Received]:
        """Every queued sample, oldest first, without blocking."""
        ...

    def close(self) -> None: ...


class Publisher(Protocol):
    key: str

    def put(self, payload: bytes) -> None: ...

    def matched(self) -> bool:
        """True if at least one subscriber currently matches this key."""
        ...

    def close(self) -> None: ...


class Token(Protocol):
    key: str

    def close(self) -> None: ...


class AliveWatch(Protocol):
    key_expr: str

    def poll(self) -> frozenset[str]:
        """Apply pending events without blocking; return the keys currently alive."""
        ...

    def drain_events(self) -> list[AliveEvent]:
        """Pending appear/vanish events (also applied to the alive set)."""
        ...

    def close(self) -> None: ...


class Bus(Protocol):
    """A session on the swarm's message bus."""

    def now_s(self) -> float:
        """The bus clock used for receive stamps."""
        ...

    def declare_publisher(
        self, key: str, congestion: Congestion = Congestion.DROP
    ) -> Publisher: ...

    def publish(self, key: str, payload: bytes) -> None:
        """Put on `key` through a publisher declared once per key, with BLOCK: for words
        sent once that must not be lost, never for a tick's data (`Congestion`)."""
        ...

    def subscribe(self, key_expr: str, capacity: int = DEFAULT_CAPACITY,
                  stamp_arrival: bool = False, hlc: bool = True) -> Subscription:
        """The newest `capacity` samples on `key_expr`; with `stamp_arrival`, each is
        stamped as it reaches this process (`Received.arrival_s`) where the bus can;
        without `hlc`, no sample carries its publisher's HLC stamp (a cost per sample that
        a reader of none, the recorder, need not pay)."""
        ...

    def declare_token(self, key: str) -> Token: ...

    def watch_alive(self, key_expr: str) -> AliveWatch: ...

    def close(self) -> None: ...

    def __enter__(self) -> Self: ...

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None: ...


def apply_alive(alive: set[str], ev: AliveEvent) -> None:
    """A watch's alive set after `ev`, bounded by MAX_ALIVE_KEYS."""
    if not ev.alive:
        alive.discard(ev.key)
    elif len(alive) < MAX_ALIVE_KEYS:
        alive.add(ev.key)


def wait_until_alive(
    watch: AliveWatch,
    expected: set[str] | frozenset[str],
    timeout_s: float,
    poll_s: float = 0.002,
) -> frozenset[str]:
    """Poll `watch` until every key of `expected` is alive; TransportError names the missing.

    For launchers and tests: the wait ends as soon as the last token shows up.
    """
    deadline = time.monotonic() + timeout_s
    while True:
        alive = watch.poll()
        missing = set(expected) - alive
        if not missing:
            return alive
        if time.monotonic() > deadline:
            raise TransportError(f"not alive after {timeout_s} s: {sorted(missing)}")
        time.sleep(poll_s)


def drain_all(subscriptions: list[Subscription]) -> list[Received]:
    """Drain several subscriptions into one list (each one oldest first)."""
    out: list[Received] = []
    for sub in subscriptions:
        out.extend(sub.drain())
    return out


class ClosingContext:
    """`with bus:` closes the bus on the way out (buses and wrappers alike)."""

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class BusBase(ClosingContext):
    """Shared plumbing of bus implementations: publisher cache and context manager."""

    def __init__(self) -> None:
        self._publishers: dict[str, Publisher] = {}

    def declare_publisher(
        self, key: str, congestion: Congestion = Congestion.DROP
    ) -> Publisher:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def publish(self, key: str, payload: bytes) -> None:
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._publishers[key] = self.declare_publisher(key, Congestion.BLOCK)
        pub.put(payload)
