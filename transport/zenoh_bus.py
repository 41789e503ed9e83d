"""The Zenoh implementation of the bus.

Every subscription uses a Zenoh RingChannel drained with `try_recv()` from the
process's loop: no Python callback ever runs on a Zenoh thread (they would
touch agent state, and they keep a process from exiting).  `close()` undeclares
everything and closes the session; use the bus as a context manager.
"""

from __future__ import annotations

import logging
import os
from collections import deque
from typing import TypeVar, Union

import zenoh

from errors import TransportError
from transport.bus import (
    DEFAULT_CAPACITY,
    AliveEvent,
    AliveWatch,
    BusBase,
    Clock,
    Congestion,
    Received,
    apply_alive,
)
from transport.clock import process_clock
from transport.clock_sync import ClockSync
from transport.fastbuild import build
from transport.key_exprs import SwarmKeys, validate_concrete
from transport.net_timeline import HidingAliveWatch
from transport.zenoh_config import RUNTIME_SETTINGS, ZenohConfig, build_zenoh_config

log = logging.getLogger(__name__)

_Owned = Union["ZenohSubscription", "ZenohPublisher", "ZenohToken", "ZenohAliveWatch",
               HidingAliveWatch]
_T = TypeVar("_T", bound=_Owned)

_CONGESTION = {
    Congestion.BLOCK: zenoh.CongestionControl.BLOCK,
    Congestion.DROP: zenoh.CongestionControl.DROP,
}


_PUT = zenoh.SampleKind.PUT


def _received(sample: zenoh.Sample, now_s: float, arrival_s: float | None,
              key: str | None, hlc: bool = True) -> Received:
    """`key`: the subscription's own where it names one key (no conversion per sample);
    None for a wildcard subscription, whose samples also carry their HLC's source (many
    publishers share such a subscription; on one key the ACL admits one publisher, whose
    sender id the message carries).  Without `hlc`, no HLC stamp or source (~1.4 of
    ~4.7 µs a sample)."""
    stamp = sample.timestamp if hlc else None
    hlc_s = None if stamp is None else stamp.get_time_as_ntp64().as_secs_f64()
    source = None if key is not None or stamp is None else str(stamp.get_id())
    return build(Received, {"key": key or str(sample.key_expr),
                            "payload": sample.payload.to_bytes(), "recv_stamp_s": now_s,
                            "hlc_stamp_s": hlc_s, "hlc_source": source,
                            "arrival_s": arrival_s})


class ZenohSubscription:
    """A ring of the newest `capacity` samples.  With arrival stamps (ZenohConfig, or
    this subscription's `stamp_arrival`), a callback stamps each sample on its way in and
    only appends to a bounded deque.  It runs on Zenoh's receiving thread
    (`indirect=False`), where the ring is filled too: the default hands every sample to a
    Python thread of its own first, a wake-up the ring's path does not have, which the
    latency would then include."""

    def __init__(self, bus: ZenohBus, key_expr: str, capacity: int,
                 stamp_arrival: bool = False, hlc: bool = True) -> None:
        self.key_expr = key_expr
        self._hlc = hlc
        self._key = None if any(c in key_expr for c in "*$") else key_expr  # _received
        self._bus = bus
        self._arrived: deque[tuple[float, zenoh.Sample]] | None = None
        self._ring: zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]] | None = None
        self._sub: zenoh.Subscriber[None] | zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]]
        if bus.cfg.arrival_stamps or stamp_arrival:
            arrived = self._arrived = deque(maxlen=capacity)
            clock = bus.now_s

            def arrive(sample: zenoh.Sample) -> None:
                arrived.append((clock(), sample))

            self._sub = bus.session.declare_subscriber(
                key_expr, zenoh.handlers.Callback(arrive, indirect=False))
        else:
            self._sub = self._ring = bus.session.declare_subscriber(
                key_expr, zenoh.handlers.RingChannel(capacity))

    def drain(self, max_items: int | None = None) -> list[Received]:
        if self._ring is None:
            return self._drain_arrived(max_items)
        if max_items is not None and max_items <= 0:
            return []
        # Called for every subscription every tick, mostly empty: no clock read then.
        try_recv = self._ring.try_recv
        sample = try_recv()
        if sample is None:
            return []
        out: list[Received] = []
        clock = self._bus.now_s
        while sample is not None:
            if sample.kind == _PUT:
                # The clock is read for each sample, after taking it: Zenoh keeps filling
                # the ring while we drain, and a starved process (ring64's recorder, 2
                # cores) preempted mid-drain took samples stamped after one early reading,
                # refused them as future-stamped (4305 in one run) and lost them.
                out.append(_received(sample, clock(), None, self._key, self._hlc))
                if max_items is not None and len(out) >= max_items:
                    break
            sample = try_recv()
        return out

    def _drain_arrived(self, max_items: int | None) -> list[Received]:
        assert self._arrived is not None
        out: list[Received] = []
        clock = self._bus.now_s
        while self._arrived and (max_items is None or len(out) < max_items):
            arrival_s, sample = self._arrived.popleft()
            if sample.kind == _PUT:
                # the clock read as in drain: never before the sample is taken
                out.append(_received(sample, clock(), arrival_s, self._key, self._hlc))
        return out

    def close(self) -> None:
        self._sub.undeclare()


class ZenohPublisher:
    def __init__(self, bus: ZenohBus, key: str, congestion: Congestion) -> None:
        self.key = validate_concrete(key)
        self.congestion = congestion
        self._pub = bus.session.declare_publisher(
            key, congestion_control=_CONGESTION[congestion]
        )

    def put(self, payload: bytes) -> None:
        try:
            self._pub.put(payload)
        except zenoh.ZError as exc:
            raise TransportError(f"put on {self.key}: {exc}") from exc

    def matched(self) -> bool:
        # The stub says bool; at runtime (1.10) it is a MatchingStatus with `.matching`.
        status: object = self._pub.matching_status
        return bool(getattr(status, "matching", status))

    def close(self) -> None:
        self._pub.undeclare()


class ZenohToken:
    def __init__(self, bus: ZenohBus, key: str) -> None:
        self.key = validate_concrete(key)
        self._token = bus.session.liveliness().declare_token(key)

    def close(self) -> None:
        self._token.undeclare()


class ZenohAliveWatch:
    def __init__(self, bus: ZenohBus, key_expr: str) -> None:
        self.key_expr = key_expr
        self._alive: set[str] = set()
        self._sub = bus.session.liveliness().declare_subscriber(
            key_expr, zenoh.handlers.FifoChannel(1024), history=True
        )

    def drain_events(self) -> list[AliveEvent]:
        events: list[AliveEvent] = []
        while (sample := self._sub.try_recv()) is not None:
            ev = AliveEvent(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)
            apply_alive(self._alive, ev)
            events.append(ev)
        return events

    def poll(self) -> frozenset[str]:
        self.drain_events()
        return frozenset(self._alive)

    def close(self) -> None:
        self._sub.undeclare()


class ZenohBus(BusBase):
    """A Zenoh session configured by `ZenohConfig`."""

    open_sessions = 0  # in this process: forking is unsafe while any is open (deploy.procs.forked)

    def __init__(self, cfg: ZenohConfig, clock: Clock | None = None) -> None:
        super().__init__()
        self.cfg = cfg
        self._clock = process_clock() if clock is None else clock  # transport.clock
        # The clock itself (time.time unless skewed): read ~20 times a follower's tick.
        self.now_s = self._clock  # type: ignore[method-assign]
        self.clock_sync: ClockSync | None = None
        self._owned: list[_Owned] = []
        # Read by Zenoh once per process, when its first session opens; yours wins if set.
        os.environ.setdefault("ZENOH_RUNTIME", RUNTIME_SETTINGS[cfg.runtime])
        try:
            self.session = zenoh.open(build_zenoh_config(cfg))
        except zenoh.ZError as exc:
            raise TransportError(f"cannot open Zenoh session: {exc}") from exc
        ZenohBus.open_sessions += 1
        self.closed = False
        log.debug("zenoh session %s listen=%s connect=%s", self.zid, cfg.listen, cfg.connect)

    @property
    def zid(self) -> str:
        return str(self.session.zid())

    def now_s(self) -> float:
        return self._clock()

    def _own(self, obj: _T) -> _T:
        self._owned.append(obj)
        return obj

    def _check_open(self) -> None:
        if self.closed:
            raise TransportError("Zenoh bus is closed")

    def declare_publisher(
        self, key: str, congestion: Congestion = Congestion.DROP
    ) -> ZenohPublisher:
        self._check_open()
        return self._own(ZenohPublisher(self, key, congestion))

    def subscribe(self, key_expr: str, capacity: int = DEFAULT_CAPACITY,
                  stamp_arrival: bool = False, hlc: bool = True) -> ZenohSubscription:
        self._check_open()
        return self._own(ZenohSubscription(self, key_expr, capacity, stamp_arrival, hlc))

    def declare_token(self, key: str) -> ZenohToken:
        self._check_open()
        return self._own(ZenohToken(self, key))

    def watch_alive(self, key_expr: str) -> AliveWatch:
        """The tokens alive; across hosts, less those of followers on a host out of reach
        (transport.clock_sync.ClockSync.follower_out_of_reach)."""
        self._check_open()
        watch = ZenohAliveWatch(self, key_expr)
        if self.clock_sync is None:
            return self._own(watch)
        return self._own(HidingAliveWatch(watch, self.clock_sync.follower_out_of_reach,
                                          self.now_s))

    def peers(self) -> list[str]:
        """Zenoh ids of the peers this session is linked to right now."""
        return [str(z) for z in self.session.info.peers_zid()]

    def start_clock_sync(self, keys: SwarmKeys, clock_id: str, n_routers: int,
                         probe: bool = False,
                         clock_of: dict[str, str] | None = None) -> ClockSync:
        """Estimate the other hosts' clock offsets from here on (transport.clock_sync):
        `clock_id` is this host's router (of `n_routers`), `probe` True on the router."""
        if self.clock_sync is None:
            self.clock_sync = ClockSync(self, keys, clock_id, probe, n_routers, clock_of)
        return self.clock_sync

    def close(self) -> None:
        if self.closed:
            return
        if self.clock_sync is not None:
            self.clock_sync.close()
        self.closed = True
        for obj in reversed(self._owned):
            try:
                obj.close()
            except zenoh.ZError as exc:  # already undeclared: nothing left to release
                log.debug("undeclare %s: %s", obj, exc)
        self._owned.clear()
        self._publishers.clear()
        try:
            self.session.close()
        except zenoh.ZError as exc:
            # Zenoh gives up closing after its timeout (peers that vanish mid-handshake as a
            # failed start is torn down); the session is gone either way, and raising here
            # would hide whatever made the caller close.
            log.warning("zenoh session close: %s", exc)
        ZenohBus.open_sessions -= 1
