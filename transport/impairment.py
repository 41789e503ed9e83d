"""Seeded network impairment on the receiving side: a `Bus` that wraps a real bus.

`ImpairedBus(bus, network, receiver=i)` is what follower i talks through.  Its
subscriptions drain the real ones and then, per link (sender, i) -- see
`transport.link_stats.link_of` -- apply the link's `agents.scenario.model.LinkImpairment`:
- loss: independent (Bernoulli `loss`) or Gilbert-Elliott, a two-state chain with
  P(bad->good) = 1/burst_len and P(good->bad) = loss / (burst_len (1 - loss)), so the
  long-run loss is `loss` and losses come in bursts of mean `burst_len`; a message is lost
  while the chain is in the bad state (P(good->bad) is capped at 1, for loss > 1/(1+1/b));
- delay: a message is held until arrival + max(0, delay + N(0, jitter)) and handed out by
  the first `drain()` after that, in release order, so jitter reorders on its own;
- reorder: with probability `reorder` a message is also held until a later message of
  its link has been released, and comes right after it (at most MAX_WAITING held per link,
  so that even reorder = 1 keeps the link alive);
- duplicate: with probability `duplicate` a delivered message is delivered twice.
Follower links use `network.impairment(j, i)`; the sensor link (from the simulator) uses
`network.default`.  Control, status, truth and liveliness are never impaired.
The run's network faults (`network.faults`, transport.net_timeline) follow the timeline:
in a partition or isolation window a cut follower link loses every message (counted
`cut`) and its liveliness token is hidden; in a degradation window the link draws from
the degradation's own seeded impairer instead of its own.

Arrival time is the publisher's Zenoh HLC stamp, capped at the drain stamp: on one host it
is within ~0.1 ms of the true arrival, whereas the drain stamp lags the arrival by up to a
loop period (and by the whole start-up for samples queued meanwhile, which are then
released at once, in order).  Across hosts the clocks' offset adds to or (down to the
drain stamp) takes from the delay.  The clock is the wrapped
bus's `now_s()`, so unit tests run it on a MemoryBus with a fake clock.

Reproducible: each link draws from its own `numpy.random.Generator` seeded with
(network.seed, link kind, sender, receiver), and every message takes the same four draws
whatever the settings, so one seed gives the same losses on a link regardless of other
links or of the jitter, duplicate and reorder settings.
"""

from __future__ import annotations

import dataclasses
import heapq
import itertools
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING

from transport.bus import (
    DEFAULT_CAPACITY,
    AliveWatch,
    Bus,
    ClosingContext,
    Congestion,
    Publisher,
    Received,
    Subscription,
    Token,
)
from transport.link_stats import Link, link_of
from transport.net_timeline import NetTimeline, cut_alive_watch
from transport.network_schema import LinkImpairment, NetworkConfig

MAX_WAITING = 16  # held-back messages per link; beyond, a message goes normally
_DRAW_BLOCK = 256
_SEED_MOD = 2**63

if TYPE_CHECKING:
    from numpy.random import Generator
_SENSOR_KIND, _FOLLOWER_KIND = 2, 1
_DEGRADED_KIND = 3
COUNTS = ("offered", "dropped", "duplicated", "reordered", "delivered", "overflow", "cut")


@dataclass
class LinkCounts:
    """What the impairment did on one link (messages)."""

    offered: int = 0  # arrived from the real bus
    dropped: int = 0  # lost by the loss model
    duplicated: int = 0  # delivered a second time
    reordered: int = 0  # held back behind a later message
    delivered: int = 0  # handed to the agent, copies included
    overflow: int = 0  # discarded because more than `capacity` were held
    cut: int = 0  # lost to a partition or isolation window


@dataclass(frozen=True)
class Fate:
    copies: int  # 0 lost, 1, or 2 duplicated
    delay_s: float
    hold: bool  # wait for the link's next message


class LinkImpairer:
    """The random fate of each message on one link: its own seeded generator and loss state."""

    def __init__(self, spec: LinkImpairment, entropy: list[int]) -> None:
        self.spec = spec
        self.identity = spec.is_identity
        self.counts = LinkCounts()
        self._entropy = entropy
        # Made at the first draw: a link left alone never draws, and a follower whose
        # links are all left alone runs without numpy (issue 15: <= 50 MB per follower).
        self._rng: Generator | None = None
        self._u: list[list[float]] = []
        self._z: list[float] = []
        self._k = 0
        burst = max(1.0, spec.burst_len)
        self._p_bad_good = 1.0 / burst
        self._p_good_bad = min(1.0, spec.loss / (burst * (1.0 - spec.loss)))
        self._bad = False

    def _draws(self) -> tuple[float, float, float, float]:
        if self._k >= len(self._z):
            if self._rng is None:
                import numpy as np

                self._rng = np.random.default_rng(self._entropy)
                self._bad = bool(self._rng.random() < self.spec.loss)  # the stationary law
            self._u, self._z, self._k = self._rng.random((_DRAW_BLOCK, 3)).tolist(), \
                self._rng.standard_normal(_DRAW_BLOCK).tolist(), 0
        u, z = self._u[self._k], self._z[self._k]
        self._k += 1
        return u[0], u[1], u[2], z

    def fate(self) -> Fate:
        u_loss, u_dup, u_hold, z = self._draws()
        spec = self.spec
        if spec.loss_model == "gilbert_elliott":
            self._bad = (u_loss >= self._p_bad_good) if self._bad else (u_loss < self._p_good_bad)
            lost = self._bad
        else:
            lost = u_loss < spec.loss
        if lost:
            return Fate(0, 0.0, False)
        delay_s = max(0.0, spec.delay_ms + spec.jitter_ms * z) / 1000.0
        return Fate(2 if u_dup < spec.duplicate else 1, delay_s, u_hold < spec.reorder)


@dataclass(order=True)
class _Held:
    release_s: float
    order: int  # arrival order: ties keep it
    rec: Received = dataclasses.field(compare=False)
    link: str = dataclasses.field(compare=False)
    primary: bool = dataclasses.field(compare=False, default=True)  # not the duplicate copy


class ImpairedSubscription:
    """A subscription whose `drain()` returns what the impaired links let through by now."""

    def __init__(self, bus: ImpairedBus, inner: Subscription, capacity: int) -> None:
        self.key_expr = inner.key_expr
        self._bus, self._inner, self._capacity = bus, inner, capacity
        self._heap: list[_Held] = []
        self._waiting: dict[str, list[_Held]] = {}  # per link: held until a later one goes
        self._ready: deque[Received] = deque()
        self._order = itertools.count()
        self._counts: dict[str, LinkCounts | None] = {}  # per key (bounded as the bus's)

    def drain(self, max_items: int | None = None) -> list[Received]:
        if self._bus.identity and max_items is None and not self._ready and not self._heap:
            return self._pass(self._inner.drain())
        now = self._bus.now_s()
        for rec in self._inner.drain():
            self._admit(rec)
        self._release(now)
        out: list[Received] = []
        while self._ready and (max_items is None or len(out) < max_items):
            out.append(self._ready.popleft())
        return out

    def _pass(self, received: list[Received]) -> list[Received]:
        """No link is impaired: what `_admit` + `_release` do then, without their work."""
        counts = self._counts
        for rec in received:
            if rec.key not in counts:
                link = self._bus.link(rec.key)
                counts[rec.key] = None if link is None else self._bus.impairer(link).counts
            link_counts = counts[rec.key]
            if link_counts is not None:
                link_counts.offered += 1
                link_counts.delivered += 1
        return received

    def _admit(self, rec: Received) -> None:
        link = self._bus.link(rec.key)
        if link is None:
            self._ready.append(rec)
            return
        imp = self._bus.impairer(link)
        counts = imp.counts  # the link's, also while a degradation draws its fates
        counts.offered += 1
        if link.sender is not None and self._bus.faults:
            now = self._bus.now_s()
            if self._bus.timeline.cut(link.sender, now):
                counts.cut += 1
                return
            imp = self._bus.degraded(link, now, imp)
        if imp.identity:
            counts.delivered += 1
            self._ready.append(rec)
            return
        fate = imp.fate()
        if fate.copies == 0:
            counts.dropped += 1
            return
        release = arrival_s(rec) + fate.delay_s
        copies = [_Held(release, next(self._order), rec, link.name, k == 0)
                  for k in range(fate.copies)]
        counts.duplicated += fate.copies - 1
        waiting = self._waiting.setdefault(link.name, [])
        if fate.hold and len(waiting) < MAX_WAITING:
            waiting.extend(copies)
        else:
            for held in copies:
                heapq.heappush(self._heap, held)
        self._bound()

    def _bound(self) -> None:
        while len(self._heap) > self._capacity:
            gone = heapq.heappop(self._heap)  # like the real queues: the oldest goes
            self._bus.impairer_by_name(gone.link).counts.overflow += 1

    def _release(self, now: float) -> None:
        while self._heap and self._heap[0].release_s <= now:
            held = heapq.heappop(self._heap)
            self._ready.append(dataclasses.replace(held.rec, recv_stamp_s=now))
            imp = self._bus.impairer_by_name(held.link)
            imp.counts.delivered += 1
            waiting = self._waiting.get(held.link)
            if waiting and waiting[0].order < held.order:
                behind = [w for w in waiting if w.order < held.order]
                self._waiting[held.link] = [w for w in waiting if w.order > held.order]
                for w in behind:
                    imp.counts.reordered += w.primary
                    w.release_s = max(w.release_s, held.release_s)
                    heapq.heappush(self._heap, w)

    def close(self) -> None:
        self._inner.close()


def arrival_s(rec: Received) -> float:
    """When the sample reached this process, as well as the bus tells (module docstring)."""
    hlc = rec.hlc_stamp_s
    return rec.recv_stamp_s if hlc is None else min(hlc, rec.recv_stamp_s)


class ImpairedBus(ClosingContext):
    """The `Bus` of receiver `receiver` (0-based follower) with its incoming links impaired."""

    def __init__(self, bus: Bus, network: NetworkConfig, receiver: int) -> None:
        self.inner, self.network, self.receiver = bus, network, receiver
        self._links: dict[str, Link | None] = {}
        self._impairers: dict[str, LinkImpairer] = {}
        specs = [network.default] + [s for _, dst, s in network.links if dst == receiver]
        faults = tuple(f for k, f in enumerate(network.faults) if k not in network.os_cut)
        self.timeline = NetTimeline(faults, receiver)
        self.faults = bool(faults)
        self._degraders: dict[tuple[str, int], LinkImpairer] = {}
        # Every link into this receiver left alone: drains pass samples through, counted.
        self.identity = all(s.is_identity for s in specs) and not self.faults
        # The inner bus's clock itself: a follower reads it ~20 times a tick.
        self.now_s = bus.now_s  # type: ignore[method-assign]

    @property
    def impaired(self) -> bool:
        """False when every link into this receiver is left alone."""
        return not self.identity

    def link(self, key: str) -> Link | None:
        if key not in self._links:
            link = link_of(key)
            # A follower hearing itself is no link.
            self._links[key] = None if link is not None and link.sender == self.receiver else link
        return self._links[key]

    def impairer(self, link: Link) -> LinkImpairer:
        imp = self._impairers.get(link.name)
        if imp is None:
            if link.sender is None:
                spec, kind, sender = self.network.default, _SENSOR_KIND, 0
            else:
                spec = self.network.impairment(link.sender, self.receiver)
                kind, sender = _FOLLOWER_KIND, link.sender
            entropy = [self.network.seed % _SEED_MOD, kind, sender, self.receiver]
            imp = self._impairers[link.name] = LinkImpairer(spec, entropy)
        return imp

    def degraded(self, link: Link, now_s: float, own: LinkImpairer) -> LinkImpairer:
        """The impairer a follower link draws from now: a degradation's, or its own."""
        assert link.sender is not None
        found = self.timeline.degradation(link.sender, now_s)
        if found is None:
            return own
        number, spec = found
        imp = self._degraders.get((link.name, number))
        if imp is None:
            entropy = [self.network.seed % _SEED_MOD, _DEGRADED_KIND, number, link.sender,
                       self.receiver]
            imp = self._degraders[(link.name, number)] = LinkImpairer(spec, entropy)
        return imp

    def set_origin(self, origin_s: float) -> None:
        """The experiment's start on this bus's clock: the network faults' time zero."""
        self.timeline.set_origin(origin_s)

    def impairer_by_name(self, name: str) -> LinkImpairer:
        return self._impairers[name]

    def stats(self) -> dict[str, LinkCounts]:
        """Per link name (`f<j>`, `sensor`), what the impairment did so far."""
        return {name: imp.counts for name, imp in sorted(self._impairers.items())}

    def counters(self) -> dict[str, int]:
        """Flat `imp_<count>_<link>` counters for a ProcessStatus (see LinkCounts)."""
        return {f"imp_{c}_{name}": getattr(counts, c)
                for name, counts in self.stats().items() for c in COUNTS}

    # ---- the Bus protocol ----------------------------------------------------------------
    def now_s(self) -> float:
        return self.inner.now_s()

    def declare_publisher(
        self, key: str, congestion: Congestion = Congestion.DROP
    ) -> Publisher:
        return self.inner.declare_publisher(key, congestion)

    def publish(self, key: str, payload: bytes) -> None:
        self.inner.publish(key, payload)

    def subscribe(self, key_expr: str, capacity: int = DEFAULT_CAPACITY,
                  stamp_arrival: bool = False, hlc: bool = True) -> ImpairedSubscription:
        # What the impairment holds back is in flight, not queued at the receiver: a small
        # receive queue (agents.follower.node.PEER_QUEUE) must not cap the emulated delay.
        held = max(capacity, DEFAULT_CAPACITY)
        inner = self.inner.subscribe(key_expr, capacity, stamp_arrival, hlc)
        return ImpairedSubscription(self, inner, held)

    def declare_token(self, key: str) -> Token:
        return self.inner.declare_token(key)

    def watch_alive(self, key_expr: str) -> AliveWatch:
        inner = self.inner.watch_alive(key_expr)
        return cut_alive_watch(inner, self.timeline, self.now_s) if self.faults else inner

    def close(self) -> None:
        self.inner.close()
