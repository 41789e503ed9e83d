"""Liveness: tokens make the member set; a stuck loop withdraws its own; a follower node
re-forms on a change."""

from __future__ import annotations

import itertools
import time

import pytest

from agents.follower.node import FollowerNode
from agents.loading.scenario_file import load_scenario
from agents.membership.liveness import (
    REFRESH_MAX_S,
    REFRESH_S,
    MembershipWatch,
    StallGuard,
    TokenSet,
)
from agents.membership.member_hold import HOLD_S, SETTLE_S
from tests.still_vehicle import still_vehicle
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import ProcessStatus, Stamper

KEYS = SwarmKeys("t")


def test_tokens_make_the_members_and_a_missing_one_is_asked_for_at_doubling_intervals(
) -> None:
    ts = TokenSet(frozenset({0, 1, 2}))
    for i in (0, 1, 2):
        ts.token(i, True)
    assert ts.tokens == {0, 1, 2} and not ts.due_refresh(0.0)
    ts.token(2, False)  # killed: asked for again after REFRESH_S, then ever more rarely
    due = [t for t in (0.1 * k for k in range(1, 1200)) if ts.due_refresh(t)]
    gaps = [b - a for a, b in itertools.pairwise(due)]
    assert due[0] == pytest.approx(0.1 + REFRESH_S, abs=0.11)
    assert gaps[:3] == pytest.approx([2 * REFRESH_S, 4 * REFRESH_S, 8 * REFRESH_S], abs=0.11)
    assert max(gaps) == pytest.approx(REFRESH_MAX_S, abs=0.11)
    ts.token(2, True)  # back: nothing to ask for, and the next miss starts short again
    assert not ts.due_refresh(200.0)
    ts.token(1, False)
    assert not ts.due_refresh(200.0) and ts.due_refresh(200.0 + REFRESH_S)



def status(bus: MemoryBus, i: int) -> None:
    msg = ProcessStatus(Stamper(f"follower-{i}").header(), "follower", i, "running", {}, "")
    bus.publish(KEYS.status("follower", i), encode(msg))


def test_watch_and_follower_node_reform_when_a_follower_leaves_and_returns() -> None:
    hub = MemoryHub()
    others = {i: MemoryBus(hub, f"f{i}") for i in (1, 2, 3)}
    tokens = {i: b.declare_token(KEYS.alive("follower", i)) for i, b in others.items()}
    bus = MemoryBus(hub, "f0")
    bus.declare_token(KEYS.alive("follower", 0))
    node = FollowerNode(load_scenario("paper"), 0, bus, still_vehicle(), "t")
    node.start_s = bus.now_s() + 1e6  # the start word was heard (membership applies)
    node.tick(bus.now_s())
    assert node.members == {0, 1, 2, 3} and node.runner.setup.neighbours == (1, 3)
    tokens[3].close()  # index 3 is killed: 0's ring neighbours are now 1 and 2
    killed_s = bus.now_s()
    node.tick(killed_s)
    assert node.members == {0, 1, 2, 3}  # a vanishing settles first (agents.membership.member_hold)
    node.tick(killed_s + SETTLE_S)
    assert node.members == {0, 1, 2}
    assert node.runner.setup.neighbours == (1, 2) and node.runner.setup.successor == 1
    assert set(node.peer_subs) == {1, 2}
    tokens[3] = others[3].declare_token(KEYS.alive("follower", 3))
    for i in (1, 2, 3):
        status(others[i], i)
    node.tick(killed_s + SETTLE_S)
    assert node.members == {0, 1, 2, 3} and node.runner.setup.neighbours == (1, 3)
    assert node.status.counters["membership_changes"] == 2
    watch = MembershipWatch(MemoryBus(hub, "sim"), KEYS, n_followers=4)
    assert watch.members(bus.now_s()) == {0, 1, 2, 3}
    node.close()


def test_a_token_whose_return_was_missed_is_found_by_asking_again() -> None:
    hub = MemoryHub()
    other = MemoryBus(hub, "f1")
    other.declare_token(KEYS.alive("follower", 1))
    watch = MembershipWatch(MemoryBus(hub, "rec"), KEYS, n_followers=2)
    assert watch.members(0.0) == {1}  # follower 0 is missing: the clock to ask runs
    watch.tracker.token(1, False)  # as if the vanish reached us but not the return
    assert watch.members(0.1) == frozenset()
    assert watch.members(0.1 + REFRESH_S) == frozenset() and watch.refreshes == 1
    assert watch.members(0.2 + REFRESH_S) == {1}  # the new watch's history


@pytest.mark.realtime
def test_a_stuck_loop_withdraws_its_token_and_declares_it_again_when_it_runs() -> None:
    hub = MemoryHub()
    now = [0.0]
    guard = StallGuard(MemoryBus(hub, "f2"), KEYS.alive("follower", 2), stall_s=5.0,
                       clock=lambda: now[0], period_s=3600.0)  # checked by hand below
    watch = MembershipWatch(MemoryBus(hub, "sim"), KEYS, n_followers=3)
    try:
        assert watch.members(0.0) == {2}
        now[0] = 4.9
        guard.check()
        assert watch.members(4.9) == {2}  # a 4.9-s stall is ridden through
        now[0] = 5.2
        guard.check()
        assert watch.members(5.2) == frozenset() and guard.withdrawals == 1
        guard.check()
        assert guard.withdrawals == 1
        guard.alive()
        assert watch.members(5.3) == {2}
    finally:
        guard.close()
    assert watch.members(5.4) == frozenset()  # closing withdraws it for good


@pytest.mark.realtime
def test_the_guards_own_thread_withdraws_the_token_of_a_loop_that_stopped() -> None:
    hub = MemoryHub()
    guard = StallGuard(MemoryBus(hub, "f2"), KEYS.alive("follower", 2), stall_s=0.2,
                       period_s=0.02)
    watch = MembershipWatch(MemoryBus(hub, "sim"), KEYS, n_followers=3)
    try:
        assert watch.members(0.0) == {2}
        deadline = time.monotonic() + 10.0
        while watch.members(0.0) and time.monotonic() < deadline:  # the loop never calls
            time.sleep(0.01)
        assert watch.members(0.0) == frozenset() and guard.withdrawals == 1
    finally:
        guard.close()


def test_a_returning_peer_numbering_from_zero_is_neither_stale_nor_duplicate() -> None:
    from transport.bus import Received
    from transport.link_stats import LinkDecoder
    from transport.messages import FollowerState, Header

    key = KEYS.follower_state(3)
    z = (0.0, 0.0)

    def rec(seq: int) -> Received:
        msg = FollowerState(Header("follower-3", seq, 1.0 + seq), 3, z, z, z, z, z, 0.0)
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
    node = FollowerNode(load_scenario("paper"), 0, bus, still_vehicle(), "t")
    node.tick(bus.now_s())  # only its own token so far
    assert node.members == {0, 1, 2, 3} and set(node.peer_subs) == {1, 3}
    node.start_s = bus.now_s() + 1e6  # the start word was heard (membership applies)
    alone_s = bus.now_s()
    for t in (alone_s, alone_s + SETTLE_S):  # the others vanished: the far side of a cut?
        node.tick(t)
        assert node.members == {0, 1, 2, 3}
    node.tick(alone_s + HOLD_S)  # not back within the hold: they left
    assert node.members == {0} and node.runner.setup.successor == 0
    assert 0 not in node.peer_subs
    others = {i: MemoryBus(hub, f"f{i}") for i in (1, 2, 3)}
    for i, b in others.items():
        b.declare_token(KEYS.alive("follower", i))
    node.tick(alone_s + HOLD_S)
    assert node.members == {0, 1, 2, 3} and set(node.peer_subs) == {1, 3}
    node.close()
