"""Liveness: tokens and heartbeats make the member set; a follower node re-forms on a change."""

from __future__ import annotations

from typing import Any, cast

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.follower import FollowerNode
from agents.liveness import SILENCE_S, LivenessTracker, MembershipWatch
from agents.mavlink.adapter import MavlinkAdapter, VehicleState
from agents.scenario_file import load_scenario
from transport.codec import encode
from transport.keys import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import ProcessStatus, Stamper

KEYS = SwarmKeys("t")


def test_token_makes_a_member_and_its_loss_removes_it() -> None:
    tr = LivenessTracker()
    tr.token(1, True, 0.0)
    tr.token(2, True, 0.0)
    assert tr.members(0.1) == {1, 2}
    tr.token(2, False, 0.2)
    assert tr.members(0.2) == {1}


def test_silence_longer_than_the_timeout_removes_and_a_heartbeat_readds() -> None:
    tr = LivenessTracker()
    tr.token(1, True, 0.0)
    tr.token(2, True, 0.0)
    for k in range(1, 100):  # the observer ticks at 10 Hz; 2 is silent, 1 is heard at 1 Hz
        t = 0.1 * k
        if k % 10 == 0:
            tr.heard(1, t)
        members = tr.members(t)
        assert members == ({1, 2} if t <= SILENCE_S else {1}), t
    tr.heard(2, 10.0)
    assert tr.members(10.0) == {1, 2}


def test_a_two_second_pause_of_a_member_is_ridden_through() -> None:
    tr = LivenessTracker()
    tr.token(1, True, 0.0)
    tr.heard(1, 0.99)  # its last status just before a 2 s stall, then 1 s until the next
    assert all(tr.members(t) == {1} for t in np.arange(1.0, 4.0, 0.02))


def test_the_observers_own_pause_does_not_make_the_others_silent() -> None:
    tr = LivenessTracker()
    tr.token(1, True, 0.0)
    assert tr.members(0.0) == {1}
    assert tr.members(8.0) == {1}  # we were stopped 8 s: nobody could be heard meanwhile


class FakeVehicle:
    def poll(self) -> VehicleState:
        return cast(Any, type("S", (), {
            "pos_enu_m": np.array([1.0, 2.0, 10.0]), "vel_enu_m_s": np.zeros(3),
            "stamp_s": 0.0, "link_ok": True}))()

    def send_velocity_enu(self, v: tuple[float, float, float]) -> bool:
        return True


def status(bus: MemoryBus, i: int) -> None:
    msg = ProcessStatus(Stamper(f"follower-{i}").header(), "follower", i, "running", {}, "")
    bus.publish(KEYS.status("follower", i), encode(msg))


def test_watch_and_follower_node_reform_when_a_follower_leaves_and_returns() -> None:
    hub = MemoryHub()
    others = {i: MemoryBus(hub, f"f{i}") for i in (1, 2, 3)}
    tokens = {i: b.declare_token(KEYS.alive("follower", i)) for i, b in others.items()}
    bus = MemoryBus(hub, "f0")
    bus.declare_token(KEYS.alive("follower", 0))
    node = FollowerNode(load_scenario("paper"), 0, bus, cast(MavlinkAdapter, FakeVehicle()), "t")
    node.start_s = bus.now_s() + 1e6  # the start word was heard (membership applies)
    node.tick(bus.now_s())
    assert node.members == {0, 1, 2, 3} and node.setup.neighbours == (1, 3)
    tokens[3].close()  # index 3 is killed: 0's ring neighbours are now 1 and 2
    node.tick(bus.now_s())
    assert node.members == {0, 1, 2}
    assert node.setup.neighbours == (1, 2) and node.setup.successor == 1
    assert set(node.peer_subs) == {1, 2}
    tokens[3] = others[3].declare_token(KEYS.alive("follower", 3))
    for i in (1, 2, 3):
        status(others[i], i)
    node.tick(bus.now_s())
    assert node.members == {0, 1, 2, 3} and node.setup.neighbours == (1, 3)
    assert node.status.counters["membership_changes"] == 2
    watch = MembershipWatch(MemoryBus(hub, "sim"), KEYS)
    assert watch.members(bus.now_s()) == {0, 1, 2, 3}
    node.close()


def test_a_status_without_a_known_token_refreshes_the_watch() -> None:
    hub = MemoryHub()
    other = MemoryBus(hub, "f1")
    other.declare_token(KEYS.alive("follower", 1))
    watch = MembershipWatch(MemoryBus(hub, "rec"), KEYS)
    assert watch.members(0.0) == {1}
    watch.tracker.token(1, False, 0.1)  # as if the vanish reached us but not the return
    assert watch.members(0.2) == frozenset()
    status(other, 1)
    watch.members(0.3)  # heard, token unknown: re-declared, history on the next poll
    assert watch.refreshes == 1 and watch.members(0.4) == {1}


def test_a_returning_peer_numbering_from_zero_is_neither_stale_nor_duplicate() -> None:
    from transport.bus import Received
    from transport.link_stats import LinkDecoder
    from transport.messages import FollowerState, Header

    key = KEYS.follower_state(3)
    z = (0.0, 0.0)

    def rec(seq: int) -> Received:
        msg = FollowerState(Header("follower-3", seq, 1.0 + seq), 3, z, z, z, z, z, z, 0.0, ())
        return Received(key, encode(msg), 2.0 + seq)

    dec = LinkDecoder()
    assert all(dec.decode(rec(k)) is not None for k in range(6))
    dec.forget(key)  # it left; a new process comes back on the same key
    assert all(dec.decode(rec(k)) is not None for k in range(3))
    counters = dec.counters()
    assert counters["rx_f3"] == 9 and counters["rx_dup_f3"] == 0 and counters["seq_stale"] == 0


def test_before_the_start_word_the_planned_ring_stands_and_alone_means_no_self_link() -> None:
    """Followers finish take-off one after another, so the tokens seen before the start
    word are partial sets (in CI: links f0->f0, f0->f2 in the run's link report).  Before
    the start the planned ring stands; after it, a follower alone in the member set is its
    own successor but never subscribes to its own key."""
    hub = MemoryHub()
    bus = MemoryBus(hub, "f0")
    bus.declare_token(KEYS.alive("follower", 0))
    node = FollowerNode(load_scenario("paper"), 0, bus, cast(MavlinkAdapter, FakeVehicle()), "t")
    node.tick(bus.now_s())  # only its own token so far
    assert node.members == {0, 1, 2, 3} and set(node.peer_subs) == {1, 3}
    node.start_s = bus.now_s() + 1e6  # the start word was heard (membership applies)
    node.tick(bus.now_s())
    assert node.members == {0} and node.setup.successor == 0
    assert 0 not in node.peer_subs
    others = {i: MemoryBus(hub, f"f{i}") for i in (1, 2, 3)}
    for i, b in others.items():
        b.declare_token(KEYS.alive("follower", i))
    node.tick(bus.now_s())
    assert node.members == {0, 1, 2, 3} and set(node.peer_subs) == {1, 3}
    node.close()


def _fresh_members(t: LivenessTracker, now_s: float) -> frozenset[int]:
    return frozenset(i for i in t.tokens if now_s - t.heard_s.get(i, now_s) <= t.silence_s)


_EVENT = st.tuples(st.sampled_from(["up", "down", "heard", "ask"]), st.integers(0, 5),
                   st.floats(0.0, 3.0, allow_nan=False))


@settings(max_examples=300, deadline=None)
@given(st.lists(_EVENT, max_size=150))
def test_the_kept_member_set_is_always_the_one_worked_out_afresh(
        events: list[tuple[str, int, float]]) -> None:
    """members() keeps its last answer between changes (a follower asks every tick); at
    every step it must equal the set worked out from scratch, pauses and all."""
    t = LivenessTracker(silence_s=5.0)
    now = 0.0
    for kind, index, dt in events:
        now += dt
        if kind == "up":
            t.token(index, True, now)
        elif kind == "down":
            t.token(index, False, now)
        elif kind == "heard":
            t.heard(index, now)
        if kind == "ask" or index % 2:  # asked at irregular times, pauses included
            assert t.members(now) == _fresh_members(t, now)


def test_a_silent_member_heard_again_is_back_at_once_not_when_the_kept_set_expires() -> None:
    t = LivenessTracker(silence_s=5.0)
    t.token(1, True, 0.0)
    t.token(2, True, 0.0)
    for k in range(1, 7):  # 2 speaks every second, 1 says nothing
        t.heard(2, float(k))
        t.members(float(k))
    assert t.members(6.0) == {2}
    t.heard(1, 6.5)
    assert t.members(6.5) == {1, 2}
