"""Deployment files (deploy.hosts.deployment) and the --hosts K layout."""

from __future__ import annotations

from typing import Any

import pytest

from agents.loading.scenario_file import load_scenario
from deploy.hosts.deployment import dump_deployment, parse_deployment, split_over_hosts
from deploy.hosts.host_launch import _links
from errors import ConfigError

pytestmark = pytest.mark.timeout(30)

DOC: dict[str, Any] = {"swarm": "s", "scenario": "paper", "hosts": [
    {"name": "ground", "address": "192.168.1.10",
     "processes": ["launcher", "sim", "recorder", "target-0", "target-1"]},
    {"name": "air", "address": "192.168.1.11", "router_port": 7448,
     "processes": ["follower-0", "follower-1", "follower-2", "follower-3"]}]}


def test_a_deployment_places_every_process_once_and_round_trips() -> None:
    dep = parse_deployment(DOC)
    dep.check(4, 2)
    assert dep.host_of("follower-2") == 1
    assert dep.router_endpoint(1, secure=True) == "tls/192.168.1.11:7448"
    import tomllib
    assert parse_deployment(tomllib.loads(dump_deployment(dep))) == dep


def test_each_vehicle_hears_its_agents_host_alone() -> None:
    """The simulator's host's agents talk to it over the loopback; the others from their
    host's address (issue 51: a vehicle's port under a flood from another address)."""
    dep = parse_deployment(DOC)
    assert dep.mav_peers(4, 2) == ("192.168.1.11",) * 4 + ("127.0.0.1",) * 2


@pytest.mark.parametrize("change, field", [
    (lambda d: d["hosts"][0].update(address="ground.local"), "hosts[0].address"),
    (lambda d: d["hosts"][1].update(router_port=0), "hosts[1].router_port"),
    (lambda d: d["hosts"][1].update(colour="red"), "hosts[1].colour"),
    (lambda d: d["hosts"][1].update(name="ground"), "hosts.name"),
])
def test_bad_fields_are_named(change: object, field: str) -> None:
    import copy
    doc = copy.deepcopy(DOC)
    change(doc)
    with pytest.raises(ConfigError, match=field.replace("[", r"\[").replace("]", r"\]")):
        parse_deployment(doc)


def test_missing_or_twice_placed_processes_are_errors() -> None:
    import copy
    doc = copy.deepcopy(DOC)
    doc["hosts"][1]["processes"] = ["follower-0", "follower-0"]
    with pytest.raises(ConfigError, match="twice"):
        parse_deployment(doc).check(4, 2)
    doc["hosts"][1]["processes"] = ["follower-0"]
    with pytest.raises(ConfigError, match="not placed: follower-1"):
        parse_deployment(doc).check(4, 2)


def test_three_hosts_put_the_ground_station_first_and_split_the_followers() -> None:
    hosts = split_over_hosts(3, 4, 2)
    assert hosts[0] == ["launcher", "sim", "recorder", "target-0", "target-1"]
    assert hosts[1:] == [["follower-0", "follower-1"], ["follower-2", "follower-3"]]
    assert sum(len(h) for h in split_over_hosts(1, 4, 2)) == 9


def test_inter_host_delay_goes_on_follower_links_across_hosts_only() -> None:
    import copy
    doc = copy.deepcopy(DOC)
    doc["inter_host_delay_ms"] = 10.0
    doc["hosts"][1]["processes"] = ["follower-0", "follower-1"]
    doc["hosts"][0]["processes"] += ["follower-2", "follower-3"]
    text = _links(parse_deployment(doc), load_scenario("paper"))
    assert text.count("[[network.links]]") == 8  # 2 x 2 pairs, both ways
    assert "from = 1\nto = 3" in text and "from = 1\nto = 2" not in text


@pytest.mark.parametrize("k_hosts", [1, 2, 3, 5])
def test_routers_link_as_a_star_around_the_first_host(k_hosts: int) -> None:
    # A tree: Zenoh 1.10's routers in a mesh lost a restarted router's routes
    # (tests/integration/test_router_restarts.py).
    hosts = [{"name": f"h{k}", "address": f"10.0.0.{k + 1}", "processes": []}
             for k in range(k_hosts)]
    dep = parse_deployment({"swarm": "s", "scenario": "paper", "hosts": hosts})
    links = [(k, j) for k in range(k_hosts) for j in dep.router_links(k)]
    assert links == [(k, 0) for k in range(1, k_hosts)]
    assert len(links) == k_hosts - 1  # connected with no cycle
