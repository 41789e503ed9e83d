"""Target observations checked for future and stale stamps as states are: one forged
stamp must not freeze a target at the follower (it keeps a target's newest observation)."""

from __future__ import annotations

import math

import pytest

from agents.follower.node import FollowerNode
from agents.loading.scenario_file import load_scenario
from tests.still_vehicle import still_vehicle
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.message_checks import DEFAULT_LIMITS, check
from transport.messages import Header, TargetObservation

pytestmark = pytest.mark.timeout(60)
KEYS = SwarmKeys("obs")
NOW = 1_800_000_000.0


def obs(seen_s: float, sent_s: float | None = None, seq: int = 0) -> TargetObservation:
    sent = seen_s if sent_s is None else sent_s
    return TargetObservation(Header("sim-0", seq, sent), 0, 0, (1.0, 2.0), seen_s)


def test_observed_stamps_are_held_to_the_state_rules() -> None:
    key, lim = KEYS.sensor_targets(0), DEFAULT_LIMITS
    assert check(obs(NOW), key, NOW) is None
    assert check(obs(NOW + lim.future_s / 2), key, NOW) is None  # clocks of hosts differ a bit
    assert check(obs(NOW + 3600.0, NOW), key, NOW) == "future_stamp"
    assert check(obs(NOW - 2 * lim.max_age_s, NOW), key, NOW) == "old_stamp"
    assert check(obs(NOW + 0.2, NOW), key, NOW) == "future_stamp"  # seen after it was sent
    assert check(obs(math.inf, NOW), key, NOW) == "nonfinite"



def test_a_future_stamped_observation_does_not_freeze_the_target() -> None:
    hub = MemoryHub()
    sim, bus = MemoryBus(hub, "sim"), MemoryBus(hub, "f0")
    node = FollowerNode(load_scenario("paper"), 0, bus, still_vehicle(),
                        KEYS.swarm)
    key = KEYS.sensor_targets(0)
    t0 = bus.now_s()
    sim.publish(key, encode(obs(t0 - 0.03, seq=0)))
    sim.publish(key, encode(obs(t0 + 1e6, t0 - 0.02, seq=1)))  # would hold the target for good
    sim.publish(key, encode(obs(t0 - 0.02, t0 + 1e6, seq=2)))  # a forged send stamp
    sim.publish(key, encode(obs(t0 - 0.01, seq=3)))
    node.ingest()
    track = node.latest.targets[0]
    assert track.stamp_s == t0 - 0.01  # the newest honest observation stands
    counters = node.counters()
    assert counters["observations_rejected"] == 2
    assert counters["drop_rejected_future_stamp"] == 2
    assert counters["rejected_from_sim-0"] == 2
    node.close()
