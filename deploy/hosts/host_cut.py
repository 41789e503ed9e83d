"""Partitions and isolations cut for real between `--hosts K` namespaces (nftables).

The hosts of `enclose run --hosts K` are linked by a bridge in a hub namespace
(deploy.hosts.namespaced_hosts); each host's veth end there is `h<k>`.  A bridge-family table in
the hub, `enclose_cut`, drops every frame between the host pairs in its set `pairs`; the
launcher fills the set when a partition or isolation starts and empties it at the heal
(`HostCut.check`, from the launcher's loop).  So Zenoh sees the cut itself: the routers'
session between the two sides times out (its lease), the far side's liveliness tokens
vanish, its clock probes stop.  Exempt: ARP, MAVLink/UDP between the followers and
their simulated autopilots, and the simulator's sensing links to the hosts' sensing
ports (TCP; sim_backend.sensor_links): on a drone the autopilot link and the sensing are on
board, not on the swarm's network.
The table is deleted when the launcher ends; it goes with the hub namespace in any case
(deploy.netns.namespace.destroy), so nothing is left behind even after a SIGKILL.

A host takes the side of its followers in each fault (transport.net_timeline.side); a
host without followers (the ground: simulator, targets, recorder) takes the first
group's side of a partition, and the others' of an isolation.  A fault whose sides
share a host cannot be cut between hosts: it is cut where messages are received, as on
one machine (`cuttable`).
"""

from __future__ import annotations

import contextlib
import itertools
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

from deploy.hosts.deployment import Deployment
from deploy.netns.namespace import _tool
from errors import DeployError
from transport.net_timeline import side
from transport.network_schema import NetFault

log = logging.getLogger("enclose.hosts")
CUT_TABLE = "enclose_cut"


def host_sides(fault: NetFault, dep: Deployment) -> list[int] | None:
    """Each host's side of `fault` (a partition or isolation); None when a host holds
    followers of two sides."""
    sides: list[int | None] = []
    for host in dep.hosts:
        found = {side(fault, i) for i in host.followers}
        if len(found) > 1:
            return None
        sides.append(found.pop() if found else None)
    ground = 1 if fault.action == "isolate" else 0  # with the others; the first group
    return [ground if s is None else s for s in sides]


def cuttable(fault: NetFault, dep: Deployment) -> bool:
    """True when `fault` separates hosts, not followers sharing one."""
    return fault.action != "degrade" and host_sides(fault, dep) is not None


def separated(fault: NetFault, dep: Deployment) -> frozenset[tuple[int, int]]:
    """The ordered host pairs (a, b) that `fault` puts on different sides."""
    sides = host_sides(fault, dep)
    if sides is None:
        return frozenset()
    return frozenset((a, b) for a, b in itertools.permutations(range(len(sides)), 2)
                     if sides[a] != sides[b])


def cut_ruleset(exempt_udp: Sequence[range], exempt_tcp: Sequence[int] = ()) -> str:
    """The hub's table: ARP, UDP to or from `exempt_udp` and TCP to or from `exempt_tcp`
    pass, frames between the bridge ports of a pair in `pairs` are dropped (and counted)."""
    rules = ["ether type arp accept"]
    for ports in exempt_udp:
        span = f"{ports.start}-{ports.stop - 1}"
        rules += [f"udp dport {span} accept", f"udp sport {span} accept"]
    for port in exempt_tcp:
        rules += [f"tcp dport {port} accept", f"tcp sport {port} accept"]
    rules.append("iifname . oifname @pairs counter drop")
    body = "".join(f"    {r}\n" for r in rules)
    return (f"table bridge {CUT_TABLE} {{\n  set pairs {{ type ifname . ifname; }}\n"
            f"  chain forward {{\n    type filter hook forward priority 0; policy accept;\n"
            f"{body}  }}\n}}\n")


def pairs_script(pairs: frozenset[tuple[int, int]]) -> str:
    """The nft commands that make the set `pairs` exactly these host pairs."""
    script = f"flush set bridge {CUT_TABLE} pairs\n"
    if pairs:
        items = ", ".join(f'"h{a}" . "h{b}"' for a, b in sorted(pairs))
        script += f"add element bridge {CUT_TABLE} pairs {{ {items} }}\n"
    return script


@dataclass
class HostCut:
    """The cuts of `faults` between the hosts of `dep`, made in namespace `hub`."""

    hub: str
    dep: Deployment
    faults: tuple[NetFault, ...]  # those `cuttable`
    exempt_udp: tuple[range, ...]
    exempt_tcp: tuple[int, ...] = ()  # the sensing ports (deploy.hosts.deployment)
    applied: frozenset[tuple[int, int]] = frozenset()
    changes: list[tuple[float, int]] = field(default_factory=list)  # (t_s, pairs cut)

    def _nft(self, script: str) -> None:
        _tool(["ip", "netns", "exec", self.hub, "nft", "-f", "-"], stdin=script)

    def open(self) -> None:
        """Make the (empty) table; DeployError if nftables refuses it."""
        self._nft(cut_ruleset(self.exempt_udp, self.exempt_tcp))
        log.info("partitions cut by nftables in %s between hosts", self.hub)

    def wanted(self, t_s: float) -> frozenset[tuple[int, int]]:
        """The host pairs cut at experiment time `t_s`."""
        pairs: set[tuple[int, int]] = set()
        for f in self.faults:
            if f.at_s <= t_s < f.end_s:
                pairs |= separated(f, self.dep)
        return frozenset(pairs)

    def check(self, t_s: float) -> None:
        """Bring the set up to date with experiment time `t_s` (a cut starts or heals)."""
        pairs = self.wanted(t_s)
        if pairs == self.applied:
            return
        self._nft(pairs_script(pairs))
        self.applied = pairs
        self.changes.append((round(t_s, 3), len(pairs)))
        log.warning("t=%.2f s: nftables cut %s", t_s,
                    ", ".join(f"h{a}->h{b}" for a, b in sorted(pairs)) or "nothing (healed)")

    def dropped(self) -> int | None:
        """Frames the table dropped so far (None if it cannot be read)."""
        try:
            text = _tool(["ip", "netns", "exec", self.hub, "nft", "list", "table", "bridge",
                          CUT_TABLE])
        except DeployError:
            return None
        for line in text.splitlines():
            if "@pairs" in line and "packets" in line:
                return int(line.split("packets", 1)[1].split()[0])
        return None

    def close(self) -> None:
        """Delete the table (tolerant: the hub's removal takes it anyway)."""
        with contextlib.suppress(DeployError):
            self._nft(f"delete table bridge {CUT_TABLE}\n")
