"""No consumer can stall a publisher: every real-time publisher of the swarm is declared
with DROP; BLOCK is left to words sent once (run control, state changes)."""

from __future__ import annotations

from typing import cast

from agents.follower.node import FollowerNode
from agents.loading.scenario_file import load_scenario
from agents.shell.process import StatusReporter
from sim_backend.swarm_sim import SensorPublisher
from tests.still_vehicle import still_vehicle
from transport.bus import Congestion, Publisher
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub, MemoryPublisher

KEYS = SwarmKeys("s")


class RecordingBus(MemoryBus):
    """A MemoryBus that remembers the congestion control of every publisher declared."""

    def __init__(self, hub: MemoryHub) -> None:
        super().__init__(hub, "rec")
        self.declared: dict[str, set[Congestion]] = {}

    def declare_publisher(self, key: str,
                          congestion: Congestion = Congestion.DROP) -> MemoryPublisher:
        self.declared.setdefault(key, set()).add(congestion)
        return super().declare_publisher(key, congestion)



def test_the_default_is_drop_and_publish_is_block() -> None:
    with RecordingBus(MemoryHub()) as bus:
        pub: Publisher = bus.declare_publisher(KEYS.truth())
        bus.publish(KEYS.control(), b"stop")
    assert cast(MemoryPublisher, pub).congestion is Congestion.DROP
    assert bus.declared[KEYS.control()] == {Congestion.BLOCK}


def test_a_follower_publishes_its_states_and_estimates_with_drop() -> None:
    with RecordingBus(MemoryHub()) as bus:
        node = FollowerNode(load_scenario("paper"), 0, bus,
                            still_vehicle(), KEYS.swarm)
        node.close()
    assert bus.declared[KEYS.follower_state(0)] == {Congestion.DROP}
    assert bus.declared[KEYS.follower_estimate(0)] == {Congestion.DROP}


def test_the_simulator_publishes_truth_and_sensing_with_drop() -> None:
    scenario = load_scenario()
    with RecordingBus(MemoryHub()) as bus:
        SensorPublisher(scenario, bus, KEYS, 1)
    assert bus.declared[KEYS.truth()] == {Congestion.DROP}
    for i in range(scenario.n):
        assert bus.declared[KEYS.sensor_targets(i)] == {Congestion.DROP}


def test_periodic_statuses_drop_state_changes_block() -> None:
    with RecordingBus(MemoryHub()) as bus:
        status = StatusReporter(bus, KEYS, "follower", 0, period_s=0.0)
        status.publish()
        status.publish()
        assert bus.declared[KEYS.status("follower", 0)] == {Congestion.DROP}
        status.set("done")
    assert bus.declared[KEYS.status("follower", 0)] == {Congestion.DROP, Congestion.BLOCK}
