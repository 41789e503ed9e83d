"""A sample's receive stamp is read when the sample is taken, never before it arrived.

Zenoh fills a subscription's ring while the process drains it.  A process preempted in
the middle of a drain (a starved recorder on 2 cores) used to stamp every sample with one
clock reading from the start of the drain: samples that arrived later looked as if sent
from the future and were refused (transport.message_checks).  The ring and the clock here are
fakes: the ring lets time pass between two samples, as a preemption would."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest
import zenoh

from transport.codec import decode, encode
from transport.message_checks import Limits, check
from transport.messages import Header, ProcessStatus
from transport.zenoh_bus import ZenohSubscription

pytestmark = pytest.mark.timeout(30)
KEY = "enclose/s/status/follower/0"


@dataclass
class FakeClock:
    t_s: float = 100.0

    def __call__(self) -> float:
        return self.t_s


@dataclass
class Payload:
    data: bytes

    def to_bytes(self) -> bytes:
        return self.data


class Sample:
    def __init__(self, payload: Payload) -> None:
        self.payload, self.key_expr, self.timestamp = payload, KEY, None
        self.kind = zenoh.SampleKind.PUT


@dataclass
class PreemptedRing:
    """Yields samples, each sent (stamped) at the clock's time; `pause_s` passes between."""

    clock: FakeClock
    count: int
    pause_s: float
    sent: list[float] = field(default_factory=list)

    def try_recv(self) -> Sample | None:
        if len(self.sent) == self.count:
            return None
        if self.sent:
            self.clock.t_s += self.pause_s  # descheduled; meanwhile the next one arrives
        self.sent.append(self.clock.t_s)
        msg = ProcessStatus(Header("follower-0", len(self.sent), self.clock.t_s), "follower",
                            0, "running", {}, "")
        return Sample(Payload(encode(msg)))


@dataclass
class FakeBus:
    now_s: FakeClock


def drain_with(ring: PreemptedRing, clock: FakeClock) -> list[float]:
    sub = object.__new__(ZenohSubscription)
    sub.key_expr, sub._arrived, sub._ring = KEY, None, ring  # type: ignore[assignment]
    sub._hlc = True
    sub._bus = FakeBus(clock)  # type: ignore[assignment]
    sub._key = KEY  # an exact key: its samples are named by it
    return [rec.recv_stamp_s for rec in sub.drain()]


def test_each_sample_is_stamped_when_taken_so_none_looks_future() -> None:
    clock = FakeClock()
    ring = PreemptedRing(clock, count=4, pause_s=0.4)
    stamps = drain_with(ring, clock)
    assert stamps == pytest.approx(ring.sent)  # not four copies of the first reading
    limits = Limits(future_s=0.5)
    for sent_s, recv_s in zip(ring.sent, stamps, strict=True):
        msg = decode(encode(ProcessStatus(Header("follower-0", 1, sent_s), "follower", 0,
                                          "running", {}, "")))
        assert check(msg, KEY, recv_s, limits) is None


def test_max_items_still_bounds_a_drain() -> None:
    clock = FakeClock()
    sub = object.__new__(ZenohSubscription)
    ring = PreemptedRing(clock, count=10, pause_s=0.0)
    sub.key_expr, sub._arrived, sub._ring = KEY, None, ring  # type: ignore[assignment]
    sub._hlc = True
    sub._bus = FakeBus(clock)  # type: ignore[assignment]
    sub._key = KEY  # an exact key: its samples are named by it
    assert len(sub.drain(3)) == 3 and len(sub.drain()) == 7
