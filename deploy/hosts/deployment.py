"""A deployment file: which process of a swarm runs on which host, and how hosts link.

```toml
swarm = "field-test"            # swarm name on the bus (the same on every host)
scenario = "paper"              # shipped name or a TOML path (the same file on every host)
inter_host_delay_ms = 0.0       # test only: added one-way delay on follower links across hosts
[[hosts]]
name = "ground"
address = "192.168.1.10"        # where the other hosts reach this one
router_port = 7447              # its Zenoh router listens here (TCP, mTLS)
processes = ["launcher", "sim", "recorder", "target-0", "target-1"]
[[hosts]]
name = "drone-a"
address = "192.168.1.11"
processes = ["follower-0", "follower-1"]
# netns = "..."; clock_offset_s = 1.3; clock_drift_ppm = 50   (test hosts only)
```

Every process of the scenario (launcher, sim, recorder, follower-i, target-j; 0-based)
is placed exactly once.  Each host runs one Zenoh router (`router-<k>`, k its position in
the file); the host's processes are its clients.  The routers form a star around the
first host's (`router_links`): in a mesh of three, Zenoh 1.10's link-state routing
lost a restarted router's routes to one of the others almost every time.  Vehicles are
the simulator's: the agents of other hosts reach them over MAVLink/UDP at the simulator
host's address, as a companion computer reaches its autopilot, and the simulator's
target sensing reaches each other host holding followers over a link of its own, to that
host's router at `router_port + 1` (`sensing_endpoint`): a vehicle's sensing is on board,
not on the swarm's network between hosts, so it never goes through another host.
"""

from __future__ import annotations

import ipaddress
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from errors import ConfigError
from transport.access import process_names
from transport.key_exprs import validate_name

DEFAULT_ROUTER_PORT = 7447
# A host's router also listens on its port + 1 for the simulator's sensing (module doc).
SENSING_PORT_OFFSET = 1
_HOST_KEYS = {"name", "address", "router_port", "processes", "netns", "clock_offset_s",
              "clock_drift_ppm"}


@dataclass(frozen=True)
class HostSpec:
    name: str
    address: str
    processes: tuple[str, ...]
    router_port: int = DEFAULT_ROUTER_PORT
    netns: str | None = None  # test hosts: the network namespace that is this host
    clock_offset_s: float = 0.0  # test hosts: injected clock offset of its processes
    clock_drift_ppm: float = 0.0

    @property
    def followers(self) -> tuple[int, ...]:
        """The indexes of the followers this host runs."""
        return tuple(int(p.removeprefix("follower-")) for p in self.processes
                     if p.startswith("follower-"))


@dataclass(frozen=True)
class Deployment:
    swarm: str
    scenario: str
    hosts: tuple[HostSpec, ...]
    inter_host_delay_ms: float = 0.0
    # Test hosts: the hub namespace whose bridge links them; partitions and isolations
    # along hosts are cut there by nftables (deploy.hosts.host_cut)
    cut_hub: str | None = None

    def host_of(self, process: str) -> int:
        for k, host in enumerate(self.hosts):
            if process in host.processes:
                return k
        raise ConfigError("deployment.hosts", f"{process} is placed on no host")

    def mav_peers(self, n: int, m: int) -> tuple[str, ...]:
        """Each vehicle's agent's address as the simulator sees it (followers, then targets):
        the loopback for an agent on the simulator's host (it talks to 127.0.0.1), else its
        host's address in this file, so that no other sender reaches a vehicle
        (sim_backend.sim_values.SimConfig.peer_hosts).  A host that reaches the simulator's
        from another of its addresses must be given that one here."""
        sim = self.host_of("sim")
        agents = [f"follower-{i}" for i in range(n)] + [f"target-{j}" for j in range(m)]
        return tuple("127.0.0.1" if k == sim else self.hosts[k].address
                     for k in map(self.host_of, agents))

    def router_endpoint(self, k: int, secure: bool) -> str:
        host = self.hosts[k]
        return f"{'tls' if secure else 'tcp'}/{host.address}:{host.router_port}"

    def router_links(self, k: int) -> tuple[int, ...]:
        """The hosts whose routers router k connects to: the first host's, from every other.

        A tree, not a mesh: with router 2 connected to routers 0 and 1, a restart of
        router 2 left the clients of router 0 or 1 deaf to router 2's clients for good
        (15 of 15 restarts on loopback, Zenoh 1.10.2; tests/integration/
        test_router_restarts.py); in a star, 26 of 26 restarts of any router healed.
        The cost: followers on two non-first hosts reach each other over two router hops.
        """
        return () if k == 0 else (0,)

    def sensing_hosts(self) -> tuple[int, ...]:
        """The hosts the simulator's sensing reaches over a link of its own: those holding
        followers, but the simulator's."""
        sim = [k for k, h in enumerate(self.hosts) if "sim" in h.processes]
        return tuple(k for k, h in enumerate(self.hosts) if k not in sim and h.followers)

    def sensing_endpoint(self, k: int, secure: bool) -> str:
        host = self.hosts[k]
        return f"{'tls' if secure else 'tcp'}/{host.address}:" \
               f"{host.router_port + SENSING_PORT_OFFSET}"

    def sensing_ports(self) -> tuple[int, ...]:
        """The TCP ports of the sensing links (exempt from a cut between hosts)."""
        return tuple(sorted({self.hosts[k].router_port + SENSING_PORT_OFFSET
                             for k in self.sensing_hosts()}))

    def router_argv(self, k: int, secure: bool) -> list[str]:
        """`deploy.hosts.router`'s endpoint arguments for router k: where it listens (and, on a
        host the simulator's sensing reaches, for it), whom it links."""
        argv = ["--listen", self.router_endpoint(k, secure)]
        if k in self.sensing_hosts():
            argv += ["--listen", self.sensing_endpoint(k, secure)]
        for j in self.router_links(k):
            argv += ["--connect", self.router_endpoint(j, secure)]
        return argv

    def index_of(self, name: str) -> int:
        for k, host in enumerate(self.hosts):
            if host.name == name:
                return k
        raise ConfigError("--host", f"{name!r} is not a host of the deployment "
                          f"({', '.join(h.name for h in self.hosts)})")

    def check(self, n: int, m: int) -> None:
        """Every process of an n-follower, m-target swarm placed exactly once."""
        wanted = process_names(n, m)
        placed = [p for h in self.hosts for p in h.processes]
        for p in placed:
            if p not in wanted:
                raise ConfigError("deployment.hosts.processes", f"{p!r} is not a process of "
                                  f"this scenario ({', '.join(wanted)})")
            if placed.count(p) > 1:
                raise ConfigError("deployment.hosts.processes", f"{p} is placed twice")
        missing = [p for p in wanted if p not in placed]
        if missing:
            raise ConfigError("deployment.hosts.processes", f"not placed: {', '.join(missing)}")


def _host(raw: Any, k: int) -> HostSpec:
    where = f"deployment.hosts[{k}]"
    if not isinstance(raw, dict):
        raise ConfigError(where, "must be a [[hosts]] table")
    unknown = set(raw) - _HOST_KEYS
    if unknown:
        raise ConfigError(f"{where}.{sorted(unknown)[0]}", "unknown key")
    try:
        address = str(ipaddress.ip_address(raw.get("address", "")))
    except ValueError:
        raise ConfigError(f"{where}.address", f"{raw.get('address')!r} is not an IP "
                          "address") from None
    port = raw.get("router_port", DEFAULT_ROUTER_PORT)
    if not isinstance(port, int) or not 1 <= port <= 65535 - SENSING_PORT_OFFSET:
        raise ConfigError(f"{where}.router_port", f"{port!r} is not a port (with the "
                          "next one free: the sensing port)")
    procs = raw.get("processes", [])
    if not isinstance(procs, list) or not all(isinstance(p, str) for p in procs):
        raise ConfigError(f"{where}.processes", "must be a list of process names")
    numbers = {}
    for key in ("clock_offset_s", "clock_drift_ppm"):
        value = raw.get(key, 0.0)
        if not isinstance(value, int | float) or not math.isfinite(value):
            raise ConfigError(f"{where}.{key}", f"{value!r} is not a number")
        numbers[key] = float(value)
    return HostSpec(validate_name(str(raw.get("name", "")), f"{where}.name"), address,
                    tuple(procs), port, raw.get("netns"), **numbers)


def parse_deployment(doc: dict[str, Any]) -> Deployment:
    hosts = doc.get("hosts")
    if not isinstance(hosts, list) or not hosts:
        raise ConfigError("deployment.hosts", "needs at least one [[hosts]] table")
    specs = tuple(_host(raw, k) for k, raw in enumerate(hosts))
    names = [h.name for h in specs]
    if len(set(names)) != len(names):
        raise ConfigError("deployment.hosts.name", "host names must differ")
    delay = doc.get("inter_host_delay_ms", 0.0)
    if not isinstance(delay, int | float) or not 0.0 <= delay < 10_000:
        raise ConfigError("deployment.inter_host_delay_ms", f"{delay!r} not in [0, 10000)")
    hub = doc.get("cut_hub")
    if hub is not None and not isinstance(hub, str):
        raise ConfigError("deployment.cut_hub", f"{hub!r} is not a namespace name")
    return Deployment(validate_name(str(doc.get("swarm", "enclose")), "deployment.swarm"),
                      str(doc.get("scenario", "paper")), specs, float(delay), hub)


def load_deployment(path: Path) -> Deployment:
    try:
        doc = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError("deployment", f"{path}: {exc}") from exc
    return parse_deployment(doc)


def dump_deployment(dep: Deployment) -> str:
    """The TOML of `dep` (for --hosts K, which writes one and runs it)."""
    lines = [f"swarm = {_q(dep.swarm)}", f"scenario = {_q(dep.scenario)}",
             f"inter_host_delay_ms = {dep.inter_host_delay_ms!r}"]
    if dep.cut_hub:
        lines.append(f"cut_hub = {_q(dep.cut_hub)}")
    for h in dep.hosts:
        lines += ["", "[[hosts]]", f"name = {_q(h.name)}", f"address = {_q(h.address)}",
                  f"router_port = {h.router_port}",
                  "processes = [" + ", ".join(_q(p) for p in h.processes) + "]",
                  f"clock_offset_s = {h.clock_offset_s!r}",
                  f"clock_drift_ppm = {h.clock_drift_ppm!r}"]
        if h.netns:
            lines.append(f"netns = {_q(h.netns)}")
    return "\n".join(lines) + "\n"


def _q(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def split_along(groups: list[list[int]], m: int) -> list[list[str]]:
    """Processes per host, one host per group of followers (0-based), the ground station
    (launcher, simulator, recorder, targets) with the first: hosts split along a partition."""
    ground = ["launcher", "sim", "recorder", *(f"target-{j}" for j in range(m))]
    hosts = [[f"follower-{i}" for i in sorted(g)] for g in groups]
    return [ground + hosts[0], *hosts[1:]]


def split_over_hosts(k: int, n: int, m: int) -> list[list[str]]:
    """Processes per host for `--hosts k`: host 0 the launcher, simulator, recorder and
    targets (the ground station); the followers in contiguous groups over hosts 1..k-1."""
    if k < 1:
        raise ConfigError("--hosts", f"must be >= 1, got {k}")
    ground = ["launcher", "sim", "recorder", *(f"target-{j}" for j in range(m))]
    if k == 1:
        return [ground + [f"follower-{i}" for i in range(n)]]
    groups: list[list[str]] = [ground] + [[] for _ in range(k - 1)]
    for i in range(n):
        groups[1 + i * (k - 1) // n].append(f"follower-{i}")
    return groups
