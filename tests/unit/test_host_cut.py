"""Which hosts a partition or isolation separates, the hub's nftables table and the set a
moment of the timeline asks for (deploy.hosts.host_cut), and hosts split along a partition."""

from __future__ import annotations

import dataclasses

import pytest

from agents.loading.scenario_file import load_scenario
from agents.scenario.net_faults import parse_net_fault_flag
from deploy.hosts.deployment import Deployment, HostSpec, split_along
from deploy.hosts.host_cut import (
    HostCut,
    cut_ruleset,
    cuttable,
    host_sides,
    pairs_script,
    separated,
)
from deploy.hosts.namespaced_hosts import HostsOptions, hosts_deployment, partition_groups

GROUND = ("launcher", "sim", "recorder", "target-0", "target-1")


def deployment(*hosts: tuple[str, ...]) -> Deployment:
    return Deployment("t", "paper", tuple(HostSpec(f"h{k}", f"10.77.0.{k + 1}", procs)
                                           for k, procs in enumerate(hosts)))


ALONG = deployment((*GROUND, "follower-0", "follower-1"), ("follower-2", "follower-3"))
THREE = deployment(GROUND, ("follower-0", "follower-1"), ("follower-2", "follower-3"))
MIXED = deployment(GROUND, ("follower-0", "follower-1", "follower-2", "follower-3"))


def test_a_partition_along_the_hosts_separates_them_and_the_ground_goes_with_the_first() -> None:
    cut = parse_net_fault_flag("40:partition:1,2|3,4:15", 4)
    assert host_sides(cut, ALONG) == [0, 1] and separated(cut, ALONG) == {(0, 1), (1, 0)}
    assert host_sides(cut, THREE) == [0, 0, 1]
    assert separated(cut, THREE) == {(0, 2), (2, 0), (1, 2), (2, 1)}
    assert cuttable(cut, ALONG) and not cuttable(cut, MIXED)  # MIXED: at the receivers
    assert separated(cut, MIXED) == frozenset()


def test_an_isolated_follower_alone_on_its_host_is_cut_from_every_other_host() -> None:
    alone = deployment((*GROUND, "follower-0", "follower-2", "follower-3"), ("follower-1",))
    iso = parse_net_fault_flag("60:isolate:follower-2:15", 4)
    assert host_sides(iso, alone) == [1, 0] and cuttable(iso, alone)
    assert not cuttable(iso, ALONG)  # follower 2 shares its host with follower 1
    assert host_sides(iso, THREE) is None
    assert not cuttable(parse_net_fault_flag("80:degrade:all:10:loss=0.3", 4), ALONG)


def test_the_hub_table_passes_arp_mavlink_and_sensing_before_it_drops_the_pairs() -> None:
    text = cut_ruleset((range(14540, 14640), range(24540, 24640)), (7448,))
    lines = [line.strip() for line in text.splitlines()]
    drop = lines.index("iifname . oifname @pairs counter drop")
    for rule in ("ether type arp accept", "udp dport 14540-14639 accept",
                 "udp sport 24540-24639 accept", "tcp dport 7448 accept",
                 "tcp sport 7448 accept"):
        assert lines.index(rule) < drop, rule
    assert "table bridge enclose_cut {" in lines
    assert pairs_script(frozenset()) == "flush set bridge enclose_cut pairs\n"
    assert 'add element bridge enclose_cut pairs { "h0" . "h1", "h1" . "h0" }' in \
        pairs_script(frozenset({(1, 0), (0, 1)}))


def test_the_set_follows_the_windows_and_each_change_is_applied_once() -> None:
    faults = (parse_net_fault_flag("40:partition:1,2|3,4:15", 4),
              parse_net_fault_flag("50:partition:1,2|3,4:10", 4))
    cut = HostCut("hub", ALONG, faults, ())
    scripts: list[str] = []
    cut._nft = scripts.append  # type: ignore[method-assign]
    for t in (0.0, 39.9, 40.0, 45.0, 55.0, 59.9, 60.0, 70.0):
        cut.check(t)
    assert cut.wanted(39.99) == frozenset() and cut.wanted(59.99) == {(0, 1), (1, 0)}
    assert [n for _, n in cut.changes] == [2, 0]  # overlapping windows: one cut, one heal
    assert [t for t, _ in cut.changes] == [40.0, 60.0]
    assert len(scripts) == 2 and "add element" in scripts[0] and "add" not in scripts[1]


@pytest.mark.parametrize(("k", "hosts"), [
    (2, [[*GROUND, "follower-0", "follower-1"], ["follower-2", "follower-3"]]),
    (3, None),  # two groups: no partition into 3, the usual split
])
def test_hosts_split_along_the_scenarios_partition(k: int, hosts: list[list[str]] | None,
                                                    ) -> None:
    paper = load_scenario("paper")
    cut = parse_net_fault_flag("40:partition:1,2|3,4:15", 4)
    scenario = dataclasses.replace(paper, network=dataclasses.replace(paper.network,
                                                                      faults=(cut,)))
    dep = hosts_deployment(HostsOptions(k), scenario, "paper", "t", "enclose-1")
    assert partition_groups(scenario, 2) == [[0, 1], [2, 3]]
    if hosts is not None:
        assert [list(h.processes) for h in dep.hosts] == hosts
        assert split_along([[0, 1], [2, 3]], 2) == hosts
    else:
        assert list(dep.hosts[0].processes) == list(GROUND)
    assert dep.cut_hub == "enclose-1-hub"
