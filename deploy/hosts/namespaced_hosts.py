"""`enclose run --hosts K`: the swarm split over K network namespaces, one host each.

Each host is a namespace `enclose-<pid>-h<k>` with a veth link `eth0` (10.77.0.<k+1>/24)
to a bridge in a hub namespace `enclose-<pid>-hub`: hosts reach each other only over
those links.  The run is a deployment (deploy.hosts.deployment) written to RUN_DIR and run
with `enclose host RUN_DIR/deployment.toml --all` inside host 0: one router per host,
processes as clients of their host's router, each host's processes on their own clock
(`--host-offsets`), MAVLink from the other hosts to the simulator over the links.
`--host-delay-ms` delays every follower link across hosts at its receiving end (the
impairment layer: this kernel has no netem).  A partition into K groups places one
group per host (the ground with the first), and its cut is made for real between the
hosts by nftables in the hub (deploy.hosts.host_cut); each host's kernel gives up a TCP
connect or a silent connection within seconds (SYN_RETRIES, TCP_RETRIES), so the routers
find each other again soon after the heal.  Every namespace is removed afterwards,
whatever happens (deploy.netns.namespace.destroy; stale ones of dead launchers at the next start).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from agents.scenario.model import Scenario
from deploy.hosts.deployment import (
    Deployment,
    HostSpec,
    dump_deployment,
    split_along,
    split_over_hosts,
)
from deploy.launch.launch_options import LaunchOptions
from deploy.netns.namespace import _tool, clean_stale, destroy, install_tools
from deploy.netns.namespace import unavailable as netns_unavailable
from deploy.netns.netns_run import run_forwarding_signals
from errors import DeployError
from transport.clock import clock_env

log = logging.getLogger("enclose.hosts")
SUBNET = "10.77.0"
# A router's attempt to reach another host's is a TCP connect Zenoh awaits without a
# timeout; begun during a partition, it waits on the kernel's SYN retries (1, 2, 4, 8,
# 16 s apart: Linux's 6), so the routers found each other up to ~16 s after the heal (the
# next SYN).  With 1 retry an attempt fails 3 s after it began and the router's next one
# follows within its 1-s retry period: SYNs never more than 3 s apart.  Per namespace:
# the host's kernel setting, as a swarm host would set it (docs/multihost.md).
SYN_RETRIES = 1
# A TCP connection whose data go unacknowledged is given up after this many retransmits
# (~3 s; Linux's 15 take ~15 min).  A router closing a TLS link lost in a partition
# writes TLS's close_notify into a socket nobody acknowledges, and Zenoh 1.10 kept the
# link's session open until that write failed: the new link made at the heal joined the
# old session, and died with it when the old socket's retransmits met the healed network
# (a reset, ~12 s after the heal), and the routers' tables did not recover within the
# run.  Given up during the cut, the old session is gone before the heal.
TCP_RETRIES = 3


def add_hosts_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("several hosts (root: one network namespace per host)")
    g.add_argument("--hosts", type=int, default=None, metavar="K",
                   help="split the swarm over K namespaced hosts linked by veth pairs")
    g.add_argument("--host-offsets", default=None, metavar="S,S,...",
                   help="clock offset of each host's processes in s (e.g. -0.8,0,1.3)")
    g.add_argument("--host-delay-ms", type=float, default=0.0,
                   help="one-way delay on follower links between hosts")


@dataclass(frozen=True)
class HostsOptions:
    """`--hosts K [--host-offsets S,S,..] [--host-delay-ms D]`."""

    count: int
    offsets: str | None = None  # each host's clock offset in s, comma-separated
    delay_ms: float = 0.0  # one-way, on follower links between hosts

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> HostsOptions | None:
        """None without --hosts."""
        if args.hosts is None:
            return None
        return cls(int(args.hosts), args.host_offsets, float(args.host_delay_ms))


def _offsets(text: str | None, k: int) -> list[float]:
    if text is None:
        return [0.0] * k
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise DeployError(f"--host-offsets: {text!r} is not a list of numbers") from None
    if len(values) != k:
        raise DeployError(f"--host-offsets: {len(values)} values for --hosts {k}")
    return values


def partition_groups(scenario: Scenario, k: int) -> list[list[int]] | None:
    """The followers' groups (0-based) of the scenario's first partition into `k` groups
    (the followers it names in no group are one more), if it has one."""
    for f in scenario.network.faults:
        if f.action != "partition":
            continue
        groups = [sorted(g) for g in f.groups]
        rest = sorted(set(range(scenario.n)).difference(*f.groups))
        groups += [rest] if rest else []
        if len(groups) == k:
            return groups
    return None


def hosts_deployment(hosts: HostsOptions, scenario: Scenario, source: str, swarm: str,
                     prefix: str) -> Deployment:
    """`scenario` (loaded from `source`: a shipped name or an absolute path) over the hosts:
    along its partition into K groups if it has one (the ground with the first group),
    else the ground on host 0 and the followers over the others."""
    k = hosts.count
    offsets = _offsets(hosts.offsets, k)
    groups = partition_groups(scenario, k)
    placed = split_along(groups, scenario.m) if groups else split_over_hosts(
        k, scenario.n, scenario.m)
    specs = tuple(HostSpec(f"h{i}", f"{SUBNET}.{i + 1}", tuple(procs), netns=f"{prefix}-h{i}",
                           clock_offset_s=offsets[i])
                  for i, procs in enumerate(placed))
    return Deployment(swarm, source, specs, hosts.delay_ms, cut_hub=f"{prefix}-hub")


@contextlib.contextmanager
def linked_namespaces(dep: Deployment, hub: str) -> Iterator[None]:
    """The hub with its bridge and one namespace per host, linked; all removed on exit."""
    install_tools()
    reason = netns_unavailable()
    if reason is not None:
        raise DeployError(f"--hosts {reason}")
    clean_stale()
    made: list[str] = []
    try:
        for name in (hub, *(h.netns for h in dep.hosts if h.netns)):
            _tool(["ip", "netns", "add", name])
            made.append(name)
            _tool(["ip", "-n", name, "link", "set", "lo", "up"])
        _tool(["ip", "-n", hub, "link", "add", "br0", "type", "bridge"])
        _tool(["ip", "-n", hub, "link", "set", "br0", "up"])
        for i, h in enumerate(dep.hosts):
            assert h.netns is not None
            _tool(["ip", "link", "add", "eth0", "netns", h.netns, "type", "veth",
                   "peer", "name", f"h{i}", "netns", hub])
            _tool(["ip", "-n", h.netns, "addr", "add", f"{h.address}/24", "dev", "eth0"])
            _tool(["ip", "-n", h.netns, "link", "set", "eth0", "up"])
            _tool(["ip", "netns", "exec", h.netns, "sysctl", "-q", "-w",
                   f"net.ipv4.tcp_syn_retries={SYN_RETRIES}",
                   f"net.ipv4.tcp_retries2={TCP_RETRIES}"])
            _tool(["ip", "-n", hub, "link", "set", f"h{i}", "master", "br0", "up"])
        log.info("hosts %s linked through %s", ", ".join(h.netns or "" for h in dep.hosts), hub)
        yield
    finally:
        for name in reversed(made):
            with contextlib.suppress(DeployError):
                destroy(name)


def inner_argv(opts: LaunchOptions, out: Path, duration_s: float) -> list[str]:
    # `enclose host` takes no network flags: the network faults go as --fault; the
    # partitions and isolations along hosts are cut by nftables in the hub (cut_hub of the
    # deployment, deploy.hosts.host_cut), the others where messages are received.
    net_faults = [arg for text in opts.network.net_faults for arg in ("--fault", text)]
    return ["host", str(out / "deployment.toml"), "--all", "--out", str(out),
            "--duration", repr(duration_s), *opts.supervision_argv(), *net_faults]


def run_on_hosts(hosts: HostsOptions, scenario: Scenario, opts: LaunchOptions, out: Path,
                 swarm: str, duration_s: float) -> int:
    """The run over `--hosts K` namespaces; the launcher runs in host 0 on its clock."""
    prefix = f"enclose-{os.getpid()}"
    dep = hosts_deployment(hosts, scenario, opts.scenario_ref(), swarm, prefix)
    out.mkdir(parents=True, exist_ok=True)
    (out / "deployment.toml").write_text(dump_deployment(dep))
    with linked_namespaces(dep, f"{prefix}-hub"):
        h0 = dep.hosts[0]
        env = [f"{a}={b}" for a, b in clock_env(h0.clock_offset_s, h0.clock_drift_ppm).items()]
        argv: Sequence[str] = ["ip", "netns", "exec", str(h0.netns), "env", *env,
                               sys.executable, "-m", "deploy.cli",
                               *inner_argv(opts, out, duration_s)]
        return run_forwarding_signals(argv)


def unavailable() -> str | None:
    return netns_unavailable()
