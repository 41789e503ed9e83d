"""Network faults: their parsing, their timeline, and the impaired bus following it."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import pytest

from agents.loading.scenario_file import build_scenario, shipped_text
from agents.scenario.net_faults import check_fault_flag, parse_net_fault_flag
from agents.shell.network_args import NetworkOptions, apply_network_arguments
from deploy.commands.run import RunOptions, run
from deploy.launch.launch_options import LaunchOptions
from errors import ScenarioError
from transport.impairment import ImpairedBus
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.net_timeline import NetTimeline, separates
from transport.network_schema import LinkImpairment, NetFault, NetworkConfig

K = SwarmKeys("netf")
pytestmark = pytest.mark.timeout(30)


def paper_with(*faults: dict[str, Any]) -> Any:
    doc = tomllib.loads(shipped_text("paper"))
    doc["faults"] = list(faults)
    return build_scenario(doc)


def test_a_partition_in_the_scenario_reaches_its_network() -> None:
    scen = paper_with({"at_s": 40, "action": "partition", "duration_s": 15,
                       "groups": [[1, 2], [3, 4]]},
                      {"at_s": 10, "action": "kill", "target": "follower-1"})
    (fault,) = scen.network.faults
    assert fault.groups == (frozenset({0, 1}), frozenset({2, 3}))
    assert (fault.at_s, fault.end_s) == (40.0, 55.0)
    assert [f.action for f in scen.faults] == ["kill"]  # the process faults stay apart
    assert fault.label() == "partition 1,2|3,4 40-55 s"


@pytest.mark.parametrize(("table", "field"), [
    ({"action": "partition", "groups": [[1, 2], [2, 3]]}, "faults[0].groups[1]"),
    ({"action": "partition", "groups": [[1, 5]]}, "faults[0].groups[0]"),
    ({"action": "isolate", "target": "follower-9"}, "faults[0].target"),
    ({"action": "degrade", "loss": 1.5}, "faults[0].loss"),
    ({"action": "degrade", "delay_ms": -3.0}, "faults[0].delay_ms"),
    ({"action": "degrade", "links": [[1, 7]]}, "faults[0].links[0]"),
    ({"action": "isolate", "target": "follower-1", "loss": 0.1}, "faults[0].loss"),
    ({"action": "isolate", "target": "follower-1", "duration_s": 190}, "faults[0].duration_s"),
])
def test_a_bad_network_fault_names_its_field(table: dict[str, Any], field: str) -> None:
    with pytest.raises(ScenarioError) as err:
        paper_with({"at_s": 40, "duration_s": 15, **table})
    assert err.value.field == field


def test_flags_give_the_same_faults_as_tables() -> None:
    part = parse_net_fault_flag("40:partition:1,2|3,4:15", 4)
    assert part == NetFault("partition", 40.0, 15.0, (frozenset({0, 1}), frozenset({2, 3})))
    iso = parse_net_fault_flag("5:isolate:follower-3:2.5", 4)
    assert iso.groups == (frozenset({2}),)
    deg = parse_net_fault_flag("5:degrade:1>2,2>1:10:loss=0.3,delay_ms=40", 4)
    assert deg.links == ((0, 1), (1, 0))
    assert deg.impairment == LinkImpairment(loss=0.3, delay_ms=40.0)
    with pytest.raises(ScenarioError):
        check_fault_flag("5:partition:1,2|2,3:10", 4, 1, "grid.fault[0]")


def test_the_command_line_adds_faults_to_the_scenarios() -> None:
    scen = paper_with({"at_s": 5, "action": "degrade", "duration_s": 1, "loss": 0.1})
    scen = apply_network_arguments(scen, NetworkOptions(net_faults=("40:isolate:follower-2:15",)))
    assert [f.action for f in scen.network.faults] == ["degrade", "isolate"]
    with pytest.raises(ScenarioError) as err:
        apply_network_arguments(scen, NetworkOptions(net_faults=("4:isolate:follower-5:1",)))
    assert err.value.field == "--net-fault.target"


def test_the_timeline_cuts_across_groups_only_inside_the_window() -> None:
    part = NetFault("partition", 10.0, 5.0, (frozenset({0, 1}), frozenset({2, 3})))
    line = NetTimeline((part,), receiver=0)
    assert not line.cut(2, 1e6)  # no origin yet: no fault holds
    line.set_origin(100.0)
    assert [line.cut(2, t) for t in (109.9, 110.0, 114.9, 115.0)] == [False, True, True, False]
    assert not line.cut(1, 112.0)  # same group
    unnamed = NetFault("partition", 0.0, 1.0, (frozenset({0}),))
    assert separates(unnamed, 0, 3) and not separates(unnamed, 2, 3)
    iso = NetFault("isolate", 0.0, 1.0, (frozenset({2}),))
    assert separates(iso, 2, 0) and separates(iso, 1, 2) and not separates(iso, 0, 1)


def test_the_last_started_degradation_holds() -> None:
    a = NetFault("degrade", 0.0, 10.0, impairment=LinkImpairment(loss=0.1))
    b = NetFault("degrade", 5.0, 2.0, links=((3, 0),), impairment=LinkImpairment(loss=0.5))
    line = NetTimeline((a, b), receiver=0)
    line.set_origin(0.0)
    assert line.degradation(3, 6.0) == (1, LinkImpairment(loss=0.5))
    assert line.degradation(2, 6.0) == (0, LinkImpairment(loss=0.1))
    assert line.degradation(3, 8.0) == (0, LinkImpairment(loss=0.1))
    assert line.degradation(3, 11.0) is None


class Clock:
    t = 0.0

    def __call__(self) -> float:
        return self.t


def test_the_impaired_bus_cuts_messages_and_tokens_in_the_window() -> None:
    clock, hub = Clock(), MemoryHub()
    part = NetFault("partition", 10.0, 5.0, (frozenset({0, 1}), frozenset({2, 3})))
    tx = MemoryBus(hub, "tx", clock)
    bus = ImpairedBus(MemoryBus(hub, "rx", clock), NetworkConfig(faults=(part,)), receiver=0)
    tokens = [tx.declare_token(f"{K.prefix}/alive/follower/{j}") for j in (1, 2)]
    sub = bus.subscribe(K.follower_state(2))
    watch = bus.watch_alive(K.alive_of("follower"))
    bus.set_origin(0.0)
    seen: list[tuple[float, set[str]]] = []
    got = 0
    for step in range(200):
        clock.t = step * 0.1
        tx.publish(K.follower_state(2), b"x")
        got += len(sub.drain())
        seen.append((clock.t, set(watch.poll())))
    cut = bus.stats()["f2"].cut
    assert 45 <= cut <= 55 and got + cut == 200
    f2 = f"{K.prefix}/alive/follower/2"
    assert all((f2 in alive) != (10.0 <= t < 15.0) for t, alive in seen)
    assert all(f"{K.prefix}/alive/follower/1" in alive for _, alive in seen)
    for token in tokens:
        token.close()
    tx.close()
    bus.close()


def test_a_degradation_draws_losses_only_in_its_window() -> None:
    clock, hub = Clock(), MemoryHub()
    deg = NetFault("degrade", 10.0, 10.0, impairment=LinkImpairment(loss=0.5))
    tx = MemoryBus(hub, "tx", clock)
    bus = ImpairedBus(MemoryBus(hub, "rx", clock), NetworkConfig(faults=(deg,), seed=3), 0)
    sub = bus.subscribe(K.follower_state(1))
    bus.set_origin(0.0)
    for step in range(300):
        clock.t = step * 0.1
        tx.publish(K.follower_state(1), b"x")
        sub.drain()
    counts = bus.stats()["f1"]
    assert counts.offered == 300
    assert 25 <= counts.dropped <= 75  # ~half of the 100 in the window, none outside
    assert counts.delivered == 300 - counts.dropped
    tx.close()
    bus.close()


def test_a_window_past_a_shorter_run_is_refused_before_anything_starts(tmp_path: Path) -> None:
    launch = LaunchOptions(network=NetworkOptions(net_faults=("20:isolate:follower-1:10",)))
    with pytest.raises(ScenarioError) as err:
        run(RunOptions(launch, duration_s=25.0, out=tmp_path / "run"))
    assert err.value.field == "--duration"
    assert not (tmp_path / "run").exists()


def test_a_fault_the_os_cuts_is_left_alone_at_the_receivers() -> None:
    scen = paper_with({"at_s": 5, "action": "degrade", "duration_s": 1, "loss": 0.1})
    scen = apply_network_arguments(scen, NetworkOptions(
        net_faults=("40:partition:1,2|3,4:15",), os_cut=(1,)))
    assert scen.network.os_cut == (1,)
    clock, hub = Clock(), MemoryHub()
    bus = ImpairedBus(MemoryBus(hub, "rx", clock), scen.network, receiver=0)
    bus.set_origin(0.0)
    assert not bus.timeline.cut(2, 45.0)  # the partition: the OS's
    assert bus.timeline.degradation(2, 5.5) is not None  # the degradation: still ours
    with pytest.raises(ScenarioError) as err:
        apply_network_arguments(scen, NetworkOptions(os_cut=(2,)))
    assert err.value.field == "--os-cut"
    bus.close()
