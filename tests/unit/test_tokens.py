"""Liveliness tokens checked, not trusted: malformed or out-of-range ones ignored and
counted, a flapping one rate-limited, the tallies kept per sender bounded."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.follower.node import FollowerNode
from agents.loading.scenario_file import load_scenario
from agents.membership.liveness import FLAP_MAX_CHANGES, FLAP_WINDOW_S, MembershipWatch, TokenSet
from tests.still_vehicle import still_vehicle
from transport.bus import MAX_ALIVE_KEYS, AliveEvent, Received
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.link_stats import LinkDecoder
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import FollowerState, Header

pytestmark = pytest.mark.timeout(120)
KEYS = SwarmKeys("tok")
N = 4


class FakeWatch:
    """Hands the watch whatever events a test makes up (keys Zenoh would deliver)."""

    key_expr = KEYS.alive_of("follower")

    def __init__(self) -> None:
        self.events: list[AliveEvent] = []

    def drain_events(self) -> list[AliveEvent]:
        out, self.events = self.events, []
        return out

    def poll(self) -> frozenset[str]:
        return frozenset()

    def close(self) -> None:
        pass


def watch_with(events: FakeWatch) -> MembershipWatch:
    watch = MembershipWatch(MemoryBus(MemoryHub()), KEYS, N)
    watch.watch = events
    return watch


tail = st.text(max_size=10) | st.binary(max_size=10).map(
    lambda b: b.decode("utf-8", "surrogateescape")) | st.sampled_from(
    ["0", "3", "4", "9", "-1", "01", "²", "٣", "3\n", "9" * 5000, "3/x", ""])
token_key = (tail.map(lambda t: f"{KEYS.prefix}/alive/follower/{t}")
             | st.text(max_size=40) | tail.map(lambda t: f"enclose/other/alive/follower/{t}"))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(token_key, st.booleans()), max_size=30))
def test_any_token_key_never_raises_and_only_the_scenarios_followers_are_members(
        events: list[tuple[str, bool]]) -> None:
    fake = FakeWatch()
    watch = watch_with(fake)
    fake.events = [AliveEvent(k, alive) for k, alive in events]
    members = watch.members(0.0)
    assert members <= set(range(N))
    good = {f"{KEYS.prefix}/alive/follower/{i}" for i in range(N)}
    appeared_bad = sum(alive for k, alive in events if k not in good)
    assert watch.counters()["tokens_rejected"] == appeared_bad
    last = {k: alive for k, alive in events if k in good}  # one read: the net effect
    assert members == {int(k.rsplit("/", 1)[1]) for k, alive in last.items() if alive}


def test_a_token_that_flaps_is_held_in_its_last_state_until_its_window_allows() -> None:
    ts = TokenSet(frozenset(range(N)))
    t = 0.0
    for k in range(FLAP_MAX_CHANGES):  # it joins, dies, restarts, stalls: all seen at once
        ts.token(2, k % 2 == 0, t)
        assert (2 in ts.tokens) is (k % 2 == 0)
        t += 0.5
    ts.token(2, True, t)  # one more inside the window: held, out still
    assert 2 not in ts.tokens and ts.held == 1
    ts.token(2, False, t + 0.1)
    ts.token(2, True, t + 0.2)
    assert 2 not in ts.tokens and ts.held == 3
    ts.settle(FLAP_WINDOW_S - 0.01)
    assert 2 not in ts.tokens
    ts.settle(FLAP_WINDOW_S + 0.01)  # the oldest change left the window: its token's state
    assert 2 in ts.tokens and ts.held == 3
    ts.token(2, False, FLAP_WINDOW_S + 0.02)  # the next one is held again (4 in 10 s)
    assert 2 in ts.tokens and ts.held == 4


def test_a_leave_and_return_within_one_read_is_no_change() -> None:
    fake = FakeWatch()
    watch = watch_with(fake)
    key = KEYS.alive("follower", 1)
    fake.events = [AliveEvent(key, True)]
    assert watch.members(0.0) == {1}
    for _ in range(50):  # toggled between two reads of the set
        fake.events += [AliveEvent(key, False), AliveEvent(key, True)]
    assert watch.members(0.1) == {1} and watch.counters()["tokens_held"] == 0



def test_a_follower_ignores_out_of_range_tokens_and_counts_them() -> None:
    """Index >= n raised in agents.membership.ring (a crash loop of every follower)."""
    hub = MemoryHub()
    others = {i: MemoryBus(hub, f"f{i}") for i in range(1, N)}
    for i, b in others.items():
        b.declare_token(KEYS.alive("follower", i))
    bus = MemoryBus(hub, "f0")
    bus.declare_token(KEYS.alive("follower", 0))
    node = FollowerNode(load_scenario("paper"), 0, bus, still_vehicle(),
                        KEYS.swarm)
    node.start_s = bus.now_s() + 1e6  # the start word was heard (membership applies)
    rogue = MemoryBus(hub, "rogue")
    for tail in ("4", "9", "123456789", "²", "٣", "01"):
        rogue.declare_token(f"{KEYS.prefix}/alive/follower/{tail}")
    node.tick(bus.now_s())
    assert node.members == set(range(N))
    assert node.counters()["tokens_rejected"] == 6
    node.close()


def test_alive_sets_and_link_tallies_stay_bounded() -> None:
    hub = MemoryHub()
    rogue, mine = MemoryBus(hub, "rogue"), MemoryBus(hub, "me")
    watch = mine.watch_alive(KEYS.all_alive())
    for k in range(MAX_ALIVE_KEYS + 50):
        rogue.declare_token(KEYS.alive("r", k))
    assert len(watch.poll()) == MAX_ALIVE_KEYS
    dec = LinkDecoder(senders={"follower-3"})
    key = KEYS.follower_state(3)
    z = (0.0, 0.0)
    for _ in range(200):  # a peer leaving and coming back, again and again
        for seq in range(2):
            msg = FollowerState(Header("follower-3", seq, 1.0), 3, z, z, z, z, z, 0.0)
            dec.decode(Received(key, encode(msg), 2.0))
        dec.forget(key)
    assert len(dec.tallies) + len(dec.retired) == 1
    assert dec.counters()["rx_f3"] == 400 and dec.counters()["rx_dup_f3"] == 0



def test_the_simulators_sensor_model_ignores_out_of_range_tokens() -> None:
    from agents.membership.member_hold import SETTLE_S
    from sim_backend.swarm_sim import SensorPublisher

    hub = MemoryHub()
    scenario = load_scenario("paper")
    sensor = SensorPublisher(scenario, MemoryBus(hub, "sim"), KEYS, 1)
    rogue = MemoryBus(hub, "rogue")
    for i in (0, 1, 3):
        rogue.declare_token(KEYS.alive("follower", i))
    for tail in ("4", "77", "²"):
        rogue.declare_token(f"{KEYS.prefix}/alive/follower/{tail}")
    sensor._follow_membership(0.0)  # raised on index 4 (agents.membership.ring)
    sensor._follow_membership(SETTLE_S)  # follower 2 vanished: a minority, settled
    assert sensor.members == {0, 1, 3}
    assert sensor.liveness.counters() == {"tokens_rejected": 3, "tokens_held": 0}
    sensor.close()
