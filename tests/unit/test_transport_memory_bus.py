"""In-memory bus: matching, drain semantics, bounded queues, liveliness, close."""

from __future__ import annotations

import pytest

from errors import TransportError
from transport.bus import AliveEvent, Bus, drain_all, wait_until_alive
from transport.codec import encode
from transport.decoder import Decoder
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import ProcessStatus, Stamper

K = SwarmKeys("t")


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_is_a_bus() -> None:
    bus: Bus = MemoryBus(MemoryHub())
    bus.close()


def test_publish_reaches_matching_subscriptions_only() -> None:
    hub, clock = MemoryHub(), FakeClock()
    with MemoryBus(hub, "a", clock) as a, MemoryBus(hub, "b", clock) as b:
        states = b.subscribe(K.all_follower_states())
        truth = b.subscribe(K.truth())
        everything = b.subscribe(K.everything())
        a.publish(K.follower_state(0), b"s0")
        clock.t = 101.0
        a.publish(K.truth(), b"t")
        a.publish("enclose/other/truth", b"foreign")
        clock.t = 102.0
        got = states.drain()
        assert [(r.key, r.payload) for r in got] == [(K.follower_state(0), b"s0")]
        assert got[0].hlc_stamp_s == 100.0 and got[0].hlc_source == "a"
        assert got[0].recv_stamp_s == 102.0
        assert [r.payload for r in truth.drain()] == [b"t"]
        assert [r.payload for r in everything.drain()] == [b"s0", b"t"]
        assert states.drain() == []


def test_drain_max_items_and_bounded_queue_keeps_newest() -> None:
    hub = MemoryHub()
    with MemoryBus(hub) as a, MemoryBus(hub) as b:
        sub = b.subscribe(K.truth(), capacity=3)
        for k in range(5):
            a.publish(K.truth(), bytes([k]))
        assert [r.payload for r in sub.drain(max_items=2)] == [b"\x02", b"\x03"]
        assert [r.payload for r in drain_all([sub])] == [b"\x04"]


def test_publisher_matched_follows_subscriptions() -> None:
    hub = MemoryHub()
    with MemoryBus(hub) as a, MemoryBus(hub) as b:
        pub = a.declare_publisher(K.follower_state(1))
        assert not pub.matched()
        sub = b.subscribe(K.all_follower_states())
        assert pub.matched()
        sub.close()
        assert not pub.matched()


def test_liveliness_history_and_close() -> None:
    hub = MemoryHub()
    launcher = MemoryBus(hub, "launcher")
    f0 = MemoryBus(hub, "f0")
    f0.declare_token(K.alive("follower", 0))
    watch = launcher.watch_alive(K.all_alive())
    assert watch.poll() == {K.alive("follower", 0)}  # history: already alive
    f1 = MemoryBus(hub, "f1")
    token = f1.declare_token(K.alive("follower", 1))
    assert watch.drain_events() == [AliveEvent(K.alive("follower", 1), True)]
    token.close()
    f0.close()  # a process exit withdraws its tokens
    assert watch.poll() == frozenset()
    launcher.close()
    f1.close()


def test_duplicate_tokens_count_until_last_close() -> None:
    hub = MemoryHub()
    with MemoryBus(hub) as a, MemoryBus(hub) as b:
        watch = b.watch_alive(K.all_alive())
        t1, t2 = a.declare_token(K.alive("sim", 0)), a.declare_token(K.alive("sim", 0))
        t1.close()
        assert watch.poll() == {K.alive("sim", 0)}
        t2.close()
        assert watch.poll() == frozenset()


def test_closed_bus_refuses_use_and_stops_receiving() -> None:
    hub = MemoryHub()
    a, b = MemoryBus(hub), MemoryBus(hub)
    sub = b.subscribe(K.truth())
    b.close()
    a.publish(K.truth(), b"x")
    assert sub.drain() == []
    with pytest.raises(TransportError):
        b.subscribe(K.truth())
    a.close()
    with pytest.raises(TransportError):
        a.publish(K.truth(), b"y")


def test_decoder_drains_subscription_and_drops_garbage() -> None:
    hub = MemoryHub()
    with MemoryBus(hub) as a, MemoryBus(hub) as b:
        sub = b.subscribe(K.all_status())
        stamper = Stamper("sim-0", clock=lambda: 1.0)
        msg = ProcessStatus(stamper.header(), "sim", 0, "running", {"ticks": 5})
        a.publish(K.status("sim", 0), b"\xc1garbage")
        a.publish(K.status("sim", 0), encode(msg))
        decoder = Decoder()
        out = decoder.drain(sub)
        assert [i.message for i in out] == [msg]
        assert decoder.counters() == {"accepted": 1, "seq_gap": 0, "seq_stale": 0,
                                      "drop_msgpack": 1, "statuses_rejected": 1}


@pytest.mark.realtime
def test_wait_until_alive_returns_or_names_the_missing() -> None:
    hub = MemoryHub()
    with MemoryBus(hub) as launcher, MemoryBus(hub) as f0:
        watch = launcher.watch_alive(K.all_alive())
        f0.declare_token(K.alive("follower", 0))
        expected = {K.alive("follower", 0), K.alive("follower", 1)}
        with pytest.raises(TransportError, match="follower/1"):
            wait_until_alive(watch, expected, timeout_s=0.01)
        f0.declare_token(K.alive("follower", 1))
        assert wait_until_alive(watch, expected, timeout_s=1.0) == expected
