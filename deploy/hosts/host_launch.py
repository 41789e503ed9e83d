"""The part of a swarm that lives on some hosts of a deployment (deploy.hosts.deployment).

`Launch` (one host, peers on loopback) is the special case; here every host runs a Zenoh
router (`deploy.hosts.router`), the host's processes are its clients (`--mode client`), and,
since hosts do not share a clock, the routers probe each other's clocks and every process
maps the other hosts' stamps by what it hears of those probes (`--clock-host`,
transport.clock_sync).  The host of the `launcher` also waits for the whole
swarm, sends the start and stop words and reports; other hosts run their processes
until those stop (the stop word) or this launcher is stopped.

A host given a network namespace in the deployment (test hosts, `enclose run --hosts K`)
has its processes started with `ip netns exec NS env ENCLOSE_CLOCK_OFFSET_S=...`: one
launcher then supervises several namespaced hosts.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from pathlib import Path

from agents.loading.scenario_file import load_scenario, parse_scenario, shipped_text
from agents.scenario.law import pinned_law
from agents.scenario.model import Scenario
from agents.shell.network_args import apply_network_arguments
from deploy.hosts.deployment import Deployment
from deploy.hosts.host_cut import HostCut, cuttable
from deploy.hosts.host_keys import HostSecrets, write_swarm_keys
from deploy.launch.launch_options import LaunchOptions
from deploy.launch.launcher import Launch, gust_window_argv
from deploy.launch.run_secrets import RunSecrets
from sim_backend.sensor_links import SensorLink
from transport.clock import clock_env
from transport.clock_sync import format_clock_hosts, parse_clock_hosts
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

log = logging.getLogger("enclose.host")
IMPAIRED_SCENARIO = "scenario-hosts.toml"
# The entry point of each kind of agent process (as deploy.launch.launcher starts them).
AGENT_MODULES = {"follower": "agents.follower.main", "target": "agents.target"}


class HostLaunch(Launch):
    # Every process starts through its host's prefix (netns, clock): none is forked.
    forks_followers = False

    def __init__(self, dep: Deployment, local: tuple[int, ...], opts: LaunchOptions,
                 out: Path, duration_s: float, every_host: bool = False) -> None:
        """`every_host`: the hosts of `local` are run from here (--all): their credentials
        are the folders of one `enclose keys` output (deploy.hosts.host_keys)."""
        self.dep, self.local, self.every_host = dep, local, every_host
        scenario = load_scenario(dep.scenario)
        dep.check(scenario.n, scenario.m)
        opts = replace(opts, scenario=dep.scenario)
        if dep.inter_host_delay_ms > 0:  # at each follower's receiving end (impairment)
            out.mkdir(parents=True, exist_ok=True)
            path = out / IMPAIRED_SCENARIO
            # The copy is elsewhere: its [law] module, if any, must name its folder.
            text = pinned_law(_source(dep.scenario), scenario.law) + _links(dep, scenario)
            path.write_text(text)
            # The file the processes load, read here from the same text.
            scenario = parse_scenario(text, origin=str(path), base=path.parent)
            opts = replace(opts, scenario=str(path))
        faults = apply_network_arguments(scenario, opts.network).network.faults
        os_cut = tuple(k for k, f in enumerate(faults) if cuttable(f, dep)) \
            if dep.cut_hub and every_host else ()
        if os_cut:  # the children leave these to the OS (transport.impairment)
            opts = replace(opts, network=replace(opts.network, os_cut=os_cut))
        super().__init__(scenario, opts, out, dep.swarm, duration_s)
        self.coordinator = self.sends_control = dep.host_of("launcher") in local
        self.sim_address = dep.hosts[dep.host_of("sim")].address
        self.host_cut: HostCut | None = None
        self.cut_dropped: int | None = None
        if os_cut and dep.cut_hub:
            exempt = tuple(range(b, b + 100) for b in (self.vehicle_base, self.adapter_base))
            self.host_cut = HostCut(dep.cut_hub, dep, tuple(faults[k] for k in os_cut), exempt,
                                    exempt_tcp=dep.sensing_ports())

    def make_secrets(self) -> RunSecrets:
        """Each local host's folder of `enclose keys` (deploy.hosts.host_keys): with --host, the
        one given; with --all, the folders of the `enclose keys` output given, or of one
        made fresh in the run directory (without the CA key: nobody adds hosts to it)."""
        if self.opts.insecure:
            return RunSecrets.make(self.out, self.keys, 0, 0, insecure=True)
        given = self.opts.credentials_dir
        if given is None:
            s = self.scenario
            root = write_swarm_keys(self.out / "credentials", self.dep, s.n, s.m,
                                    keep_ca_key=False)
            folders = {k: root[self.dep.hosts[k].name] for k in self.local}
        elif self.every_host:
            folders = {k: Path(given) / self.dep.hosts[k].name for k in self.local}
        else:
            folders = {self.local[0]: Path(given)}
        return HostSecrets.of(self.dep, self.local, folders)

    def prefix(self, k: int) -> list[str]:
        host = self.dep.hosts[k]
        env = ["env", *(f"{a}={b}" for a, b in
                        clock_env(host.clock_offset_s, host.clock_drift_ppm).items())]
        return (["ip", "netns", "exec", host.netns] if host.netns else []) + env

    def client_args(self, name: str) -> list[str]:
        k = self.dep.host_of(name)
        clock = ["--clock-host", str(k), "--clock-hosts", self.clock_hosts()]
        return [*self.common(), "--mode", "client", "--connect", self.router(k),
                *(clock if self.clocks_differ() else []), *self.secrets.args_for(name)]

    def clocks_differ(self) -> bool:
        """More than one host: more than one clock (one host's processes share it)."""
        return len(self.dep.hosts) > 1

    def clock_hosts(self) -> str:
        """Every host's sender ids (`--clock-hosts`): whose stamps run on which clock."""
        return format_clock_hosts([[_sender(p) for p in h.processes] for h in self.dep.hosts])

    def router(self, k: int) -> str:
        return self.dep.router_endpoint(k, secure=not self.opts.insecure)

    def start_all(self) -> None:
        for k in self.local:
            argv = [*self.dep.router_argv(k, secure=not self.opts.insecure),
                    "--swarm", self.keys.swarm, *self.secrets.args_for(f"router-{k}")]
            if self.clocks_differ():
                argv += ["--clock-id", f"router-{k}", "--clock-routers", str(len(self.dep.hosts))]
            self.sup.start(f"router-{k}", "deploy.hosts.router", argv, prefix=self.prefix(k))
        mav = ["--mav-local-base", str(self.adapter_base),
               "--mav-vehicle-base", str(self.vehicle_base)]
        for k in self.local:
            for name in self.dep.hosts[k].processes:
                self._start(name, k, mav)

    def _start(self, name: str, k: int, mav: list[str]) -> None:
        argv, pre = self.client_args(name), self.prefix(k)
        remote = k != self.dep.host_of("sim")
        if name == "sim":
            self.sup.start(name, "sim_backend.swarm_sim", [
                *argv, "--mav-host", "0.0.0.0", "--base-port", str(self.vehicle_base),
                "--send-base-port", str(self.adapter_base), "--mav-peers",
                ",".join(self.dep.mav_peers(self.scenario.n, self.scenario.m)),
                "--noise-std-m", str(self.opts.noise_std_m), *self.sensor_link_argv(),
                *gust_window_argv(self.faults)],
                prefix=pre)
        elif name == "recorder":
            self.sup.start(name, "deploy.recording.recorder",
                           [*argv, "--out", str(self.out), *self.recorder_output_argv()],
                           prefix=pre)
        elif name != "launcher":
            role, _, idx = name.rpartition("-")
            extra = ["--mav-vehicle-host", self.sim_address] if remote else []
            extra += self.journal_argv() if role == "follower" else []
            self.sup.start(name, AGENT_MODULES[role], [*argv, *mav, *extra, "--index", idx],
                           prefix=pre)

    def sensor_link_argv(self) -> list[str]:
        """The simulator's sensing of each other host's followers, over a link to that
        host (sim_backend.sensor_links)."""
        argv: list[str] = []
        for k in self.dep.sensing_hosts():
            endpoint = self.dep.sensing_endpoint(k, secure=not self.opts.insecure)
            argv += SensorLink(endpoint, self.dep.hosts[k].followers).argv()
        return argv

    def open_bus(self) -> ZenohBus:
        """The coordinator's session as the launcher; another host's as its router (the
        one identity every host holds: a host without the launcher never has its key),
        which only watches its own processes link and stop (`sends_control`)."""
        k = self.dep.host_of("launcher") if self.coordinator else self.local[0]
        name = "launcher" if self.coordinator else f"router-{k}"
        bus = ZenohBus(ZenohConfig(  # our clock: the environment's (transport.clock)
            mode="client", connect=(self.router(k),), user_config_path=self.opts.zenoh_config,
            identity=self.secrets.identity(name),
            runtime=self.scenario.network.zenoh_runtime,
            lease_s=self.scenario.network.zenoh_lease_s))
        if self.clocks_differ():
            bus.start_clock_sync(self.keys, f"router-{k}", len(self.dep.hosts),
                                 clock_of=parse_clock_hosts(self.clock_hosts()))
        return bus

    def expected_tokens(self) -> set[str]:
        if self.coordinator:
            return super().expected_tokens()
        local = {_sender(p) for k in self.local for p in self.dep.hosts[k].processes}
        return {t for t in super().expected_tokens()
                if t.rsplit("/", 2)[-2] + "-" + t.rsplit("/", 1)[-1] in local}

    def fly(self, bus: object) -> None:
        if self.coordinator:
            cut = self.host_cut
            if cut is not None:
                cut.open()
            try:
                super().fly(bus)  # type: ignore[arg-type]
            finally:
                if cut is not None:
                    self.cut_dropped = cut.dropped()
                    cut.close()
            return
        # Not the coordinator: supervise until our movers have stopped (stop word).
        movers = [c for c in self.sup.children if c.name.startswith(("follower", "target"))]
        while any(c.poll() is None for c in movers):
            time.sleep(0.2)

    def report(self) -> dict[str, object]:
        out = super().report()
        out["hosts"] = {h.name: {"address": h.address, "processes": list(h.processes),
                                 "clock_offset_s": h.clock_offset_s, "netns": h.netns}
                        for h in self.dep.hosts}
        out["inter_host_delay_ms"] = self.dep.inter_host_delay_ms
        if self.host_cut is not None:
            out["os_cut"] = {"hub": self.host_cut.hub, "changes": self.host_cut.changes,
                             "frames_dropped": self.cut_dropped}
        return out

    def cut_check(self, t_s: float) -> None:
        if self.host_cut is not None:
            self.host_cut.check(t_s)


def _sender(name: str) -> str:
    """The sender id process `name` stamps its messages with (`sim` -> `sim-0`)."""
    return name if name.rpartition("-")[2].isdigit() else f"{name}-0"


def _source(scenario: str) -> str:
    if scenario.endswith(".toml"):
        return Path(scenario).read_text()
    return shipped_text(scenario)


def _links(dep: Deployment, s: Scenario) -> str:
    """`[[network.links]]` overrides: the delay on every follower link across hosts
    (file numbering is 1-based)."""
    out = []
    for i in range(s.n):
        for j in range(s.n):
            if i != j and dep.host_of(f"follower-{i}") != dep.host_of(f"follower-{j}"):
                out.append(f"\n[[network.links]]\nfrom = {j + 1}\nto = {i + 1}\n"
                           f"delay_ms = {dep.inter_host_delay_ms!r}\n")
    return "".join(out)
