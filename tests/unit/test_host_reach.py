"""A host out of reach hides its followers' liveliness tokens (transport.clock_sync's
`follower_out_of_reach` under transport.net_timeline's HidingAliveWatch): gone once its
router's probes have stopped for REACH_S, back when they are heard again; followers on
our own host and senders of no host are never hidden."""

from __future__ import annotations

import time

import pytest

from transport.clock_sync import REACH_S, ClockSync, parse_clock_hosts
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import ClockProbe, Header
from transport.net_timeline import HidingAliveWatch
from transport.peer_clock import ClockBook
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

pytestmark = [pytest.mark.timeout(30), pytest.mark.realtime]
KEYS = SwarmKeys("s")


class FakeClock:
    def __init__(self) -> None:
        self.t_s = 100.0

    def __call__(self) -> float:
        return self.t_s


def probe_from_router_1(bus: MemoryBus, now_s: float) -> None:
    bus.publish(KEYS.clock("router", 1), encode(ClockProbe(Header("router-1", 0, now_s),
                                                           50.0, ())))


def wait_until(cond: object, timeout_s: float = 5.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():  # type: ignore[operator]
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.005)


def test_followers_of_a_silent_host_are_hidden_and_come_back_with_its_probes() -> None:
    clock, hub = FakeClock(), MemoryHub()
    hosts = parse_clock_hosts("sim-0,follower-0,follower-1;follower-2,follower-3")
    with MemoryBus(hub, "f0", clock=clock) as bus, MemoryBus(hub, "r1", clock=clock) as r1, \
            MemoryBus(hub, "f2", clock=clock) as f2:
        sync = ClockSync(bus, KEYS, "router-0", False, 2, hosts, book=ClockBook(),
                         period_s=0.005)
        try:
            watch = HidingAliveWatch(bus.watch_alive(KEYS.all_alive()),
                                     sync.follower_out_of_reach, bus.now_s)
            f2.declare_token(KEYS.alive("follower", 2))
            bus.declare_token(KEYS.alive("follower", 0))
            far, near = KEYS.alive("follower", 2), KEYS.alive("follower", 0)
            assert watch.poll() == {near}  # host 1 not heard yet
            probe_from_router_1(r1, clock())
            wait_until(lambda: far in watch.poll())
            clock.t_s += REACH_S - 0.1  # silent, not yet for REACH_S
            assert watch.poll() == {near, far}
            clock.t_s += 0.2  # the cut: out of reach
            assert watch.poll() == {near}
            assert not sync.follower_out_of_reach(0, clock()) and \
                sync.follower_out_of_reach(3, clock())
            assert not sync.follower_out_of_reach(9, clock())  # on no host: never hidden
            probe_from_router_1(r1, clock())  # the heal
            wait_until(lambda: watch.poll() == {near, far})
        finally:
            sync.close()


def test_a_bus_that_syncs_clocks_across_hosts_watches_tokens_through_the_reach() -> None:
    hosts = parse_clock_hosts("follower-0;follower-1")
    with ZenohBus(ZenohConfig()) as bus:
        plain = bus.watch_alive(KEYS.all_alive())
        assert not isinstance(plain, HidingAliveWatch)  # one host: Zenoh's tokens as they are
        # As start_clock_sync, with a book of the test's own (not the process's).
        bus.clock_sync = ClockSync(bus, KEYS, "router-0", False, 2, hosts, book=ClockBook())
        watch = bus.watch_alive(KEYS.all_alive())
        assert isinstance(watch, HidingAliveWatch)
        bus.declare_token(KEYS.alive("follower", 1))
        bus.declare_token(KEYS.alive("follower", 0))
        # Follower 1's host (router-1) is never heard: its token stays hidden.
        wait_until(lambda: KEYS.alive("follower", 0) in watch.poll())
        assert KEYS.alive("follower", 1) not in watch.poll()
        assert KEYS.alive("follower", 1) in plain.poll()
