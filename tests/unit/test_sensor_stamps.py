"""The simulator's truth and target observations are stamped with the time they are true."""

from __future__ import annotations

from agents.scenario_file import load_scenario
from deploy.swarm_sim import SensorPublisher
from sim_backend.model import FleetState
from sim_backend.runtime import spawn_points_ned
from transport.codec import decode
from transport.keys import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import TargetObservation, TruthSnapshot


def test_a_late_tick_is_stamped_with_its_state_time_not_its_publish_time() -> None:
    scenario = load_scenario()
    keys = SwarmKeys("s")
    hub = MemoryHub()
    with MemoryBus(hub, "sim", clock=lambda: 1000.0) as bus, MemoryBus(hub, "rx") as rx:
        sub = rx.subscribe("enclose/s/**")
        sensor = SensorPublisher(scenario, bus, keys, 1, late_s=lambda t: 0.015)
        sensor(2.0, FleetState.on_ground(spawn_points_ned(scenario)))
        msgs = [decode(r.payload) for r in sub.drain()]
    truth = [m for m in msgs if isinstance(m, TruthSnapshot)]
    seen = [m for m in msgs if isinstance(m, TargetObservation)]
    assert truth and seen
    assert truth[0].header.stamp_s == 1000.0 - 0.015
    assert {m.observed_stamp_s for m in seen} == {1000.0 - 0.015}
