"""The simulator's truth and target observations are stamped with the time they are true."""

from __future__ import annotations

import pytest

from agents.loading.scenario_file import load_scenario
from sim_backend.kinematics import FleetState
from sim_backend.runtime import spawn_points_ned
from sim_backend.swarm_sim import SensorPublisher, sensor_every_ticks, sim_tick_hz
from transport.codec import decode
from transport.key_exprs import SwarmKeys
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


@pytest.mark.parametrize(("sensor_hz", "every", "effective_hz"),
                         [(50.0, 1, 50.0), (20.0, 2, 25.0), (30.0, 1, 50.0), (25.0, 2, 25.0),
                          (10.0, 5, 10.0), (100.0, 1, 50.0)])
def test_observations_come_at_least_as_often_as_asked_and_at_most_once_a_tick(
        sensor_hz: float, every: int, effective_hz: float) -> None:
    assert sensor_every_ticks(50.0, sensor_hz) == every
    assert 50.0 / every == effective_hz >= min(sensor_hz, 50.0)


@pytest.mark.parametrize(("control_hz", "tick_hz"),
                         [(20.0, 40.0), (50.0, 50.0), (25.0, 50.0), (30.0, 30.0), (10.0, 50.0),
                          (7.0, 49.0), (100.0, 50.0)])
def test_the_simulator_ticks_on_a_whole_multiple_of_the_control_rate(
        control_hz: float, tick_hz: float) -> None:
    assert sim_tick_hz(control_hz) == pytest.approx(tick_hz)
    if control_hz <= 50.0:  # one observation per control period, exactly
        every = sensor_every_ticks(sim_tick_hz(control_hz), control_hz)
        assert sim_tick_hz(control_hz) / every == pytest.approx(control_hz)
