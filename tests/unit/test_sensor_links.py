"""The simulator's sensing of followers on other hosts goes over a link to their host
(sim_backend.sensor_links): the flag, the deployment's sensing endpoints, and the observations
of a linked follower published on its link's bus only; the link's session opened in the
background, so the simulator never waits for another host."""

from __future__ import annotations

import time

import pytest

from agents.loading.scenario_file import load_scenario
from deploy.hosts.deployment import Deployment, HostSpec
from deploy.launch.ports import free_tcp_port
from errors import ConfigError
from sim_backend.kinematics import FleetState
from sim_backend.runtime import spawn_points_ned
from sim_backend.sensor_links import LinkBus, SensorLink, check_disjoint, parse_sensor_link
from sim_backend.swarm_sim import SensorPublisher
from transport.codec import decode
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import TargetObservation
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

GROUND = ("launcher", "sim", "recorder", "target-0", "target-1")


def test_a_link_round_trips_through_its_flag_and_bad_ones_are_named() -> None:
    link = SensorLink("tls/10.77.0.2:7448", (2, 3))
    flag, text = link.argv()
    assert flag == "--sensor-link" and parse_sensor_link(text, 4) == link
    for bad in ("tls/10.77.0.2:7448", "10.77.0.2=1", "tls/a:1=x", "tls/a:1=4", "tls/a:1=-1"):
        with pytest.raises(ConfigError, match="--sensor-link"):
            parse_sensor_link(bad, 4)
    with pytest.raises(ConfigError, match="follower 2"):
        check_disjoint([link, SensorLink("tls/10.77.0.3:7448", (2,))])


def test_hosts_with_followers_but_not_the_simulator_listen_for_its_sensing() -> None:
    dep = Deployment("t", "paper", (
        HostSpec("h0", "10.77.0.1", (*GROUND, "follower-0")),
        HostSpec("h1", "10.77.0.2", ("follower-1", "follower-2"), router_port=7500),
        HostSpec("h2", "10.77.0.3", ("follower-3",))))
    assert dep.sensing_hosts() == (1, 2)
    assert dep.sensing_endpoint(1, secure=True) == "tls/10.77.0.2:7501"
    assert dep.sensing_ports() == (7448, 7501)
    assert dep.router_argv(1, secure=False) == [
        "--listen", "tcp/10.77.0.2:7500", "--listen", "tcp/10.77.0.2:7501",
        "--connect", "tcp/10.77.0.1:7447"]
    assert dep.router_argv(0, secure=False) == ["--listen", "tcp/10.77.0.1:7447"]


def observer(payload: bytes) -> int:
    msg = decode(payload)
    assert isinstance(msg, TargetObservation)
    return msg.observer_index


def test_a_linked_followers_observations_go_on_its_links_bus_only() -> None:
    scenario = load_scenario()
    keys = SwarmKeys("s")
    ground, far = MemoryHub(), MemoryHub()  # the simulator's host and another
    with MemoryBus(ground, "sim") as bus, MemoryBus(far, "sim-link") as link, \
            MemoryBus(ground, "rx0") as rx0, MemoryBus(far, "rx1") as rx1:
        subs = [rx.subscribe(keys.all_sensor_targets()) for rx in (rx0, rx1)]
        sensor = SensorPublisher(scenario, bus, keys, 1, sensor_buses={2: link, 3: link})
        sensor(2.0, FleetState.on_ground(spawn_points_ned(scenario)))
        got = [{observer(r.payload) for r in sub.drain()} for sub in subs]
        sensor.close()
    observers = {i for t in scenario.targets for i in t.observed_by}
    assert got[1] == observers & {2, 3} and got[1]
    assert got[0] == observers - {2, 3} and got[0]


@pytest.mark.realtime  # a Zenoh session and the link's opening thread
@pytest.mark.timeout(60)
def test_a_sensing_link_opens_in_the_background_and_drops_until_it_is_up() -> None:
    port = free_tcp_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    link = LinkBus(ZenohConfig(mode="client", connect=(endpoint,)))
    try:
        pub = link.declare_publisher("s/sensor/2/targets")  # nothing listens there yet
        pub.put(b"early")
        assert link.dropped == 1 and not link.wait_open(0.2)
        with ZenohBus(ZenohConfig(mode="peer", listen=(endpoint,))) as far:
            sub = far.subscribe("s/sensor/**")
            assert link.wait_open(30.0)
            got: list[bytes] = []
            deadline = time.monotonic() + 20.0
            while not got and time.monotonic() < deadline:
                pub.put(b"late")
                got += [r.payload for r in sub.drain()]
                time.sleep(0.05)
            assert got and set(got) == {b"late"}
    finally:
        link.close()
    assert not link._thread.is_alive()
