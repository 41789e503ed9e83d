"""Command lines become typed options once; children are given back the flags they need;
a process loads its scenario once."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from agents.scenario.model import Scenario
from agents.shell.network_args import NetworkOptions
from agents.shell.process_options import AgentOptions, BusOptions
from deploy.cli import build_parser
from deploy.commands.host import HostOptions
from deploy.commands.run import RunOptions
from deploy.hosts import namespaced_hosts
from deploy.launch.launch_options import LaunchOptions
from deploy.launch.live_args import LiveOptions
from deploy.netns import netns_run
from errors import TransportError

RUN_FLAGS = ["--duration", "12.5", "--swarm", "sw", "--port-range", "20000-20999",
             "--noise-std-m", "0.2", "--link-timeout", "30", "--insecure", "--json",
             "--restart", "never", "--max-restarts", "2", "--fault", "3:kill:follower-1",
             "--fault", "5:pause:target-0:1", "--estimator", "paper", "--loss", "0.05",
             "--live-port", "9000", "--no-journal"]


def run_options(*argv: str) -> RunOptions:
    return RunOptions.from_namespace(build_parser(["run"]).parse_args(["run", *argv]))


def test_enclose_run_reads_every_flag_into_its_options(tmp_path: Path) -> None:
    opts = run_options(str(tmp_path / "s.toml"), "--out", str(tmp_path), *RUN_FLAGS)
    launch = opts.launch
    assert (opts.duration_s, opts.out, opts.swarm) == (12.5, tmp_path, "sw")
    assert (opts.netns, opts.hosts) == (None, None)
    assert launch == LaunchOptions(
        scenario=str(tmp_path / "s.toml"), noise_std_m=0.2, link_timeout_s=30.0,
        insecure=True, json=True, restart="never", max_restarts=2,
        faults=("3:kill:follower-1", "5:pause:target-0:1"),
        network=NetworkOptions(estimator="paper", impairment=(("loss", 0.05),)),
        live=LiveOptions(port=9000), port_range="20000-20999", journal=False)
    assert run_options("--no-live").launch.live is None
    assert run_options().launch.journal is None  # the scenario's [run] journal decides
    hosts = run_options("--hosts", "3", "--host-offsets", "0,1,2", "--host-delay-ms", "4").hosts
    assert hosts == namespaced_hosts.HostsOptions(3, "0,1,2", 4.0)


def test_a_run_started_again_in_a_namespace_gets_the_same_options(tmp_path: Path) -> None:
    scen = tmp_path / "s.toml"
    first = run_options(str(scen), "--netns", *RUN_FLAGS)
    argv = netns_run.inner_argv(first.launch, tmp_path / "out", "sw", 12.5)
    again = RunOptions.from_namespace(build_parser(argv).parse_args(argv))
    # Inside, no namespace again and no live view (its loopback is not this machine's).
    assert again.netns is None and again.launch.live is None
    assert again.launch == LaunchOptions(**{**first.launch.__dict__, "live": None,
                                           "port_range": None})
    assert (again.duration_s, again.out, again.swarm) == (12.5, tmp_path / "out", "sw")


def test_hosts_get_the_launchers_supervision_flags(tmp_path: Path) -> None:
    first = run_options("--hosts", "2", *RUN_FLAGS).launch
    argv = namespaced_hosts.inner_argv(first, tmp_path, 12.5)
    host = HostOptions.from_namespace(build_parser(argv).parse_args(argv))
    assert host.host is None and host.deployment == tmp_path / "deployment.toml"
    shared = ("noise_std_m", "link_timeout_s", "insecure", "restart", "max_restarts", "faults",
              "journal")
    assert {k: getattr(host.launch, k) for k in shared} == {k: getattr(first, k) for k in shared}
    assert host.launch.live is None and host.launch.network == NetworkOptions()


class Stop(TransportError):
    """Raised by the stand-in bus: the process got as far as opening it."""


def count_loads(monkeypatch: pytest.MonkeyPatch) -> list[Scenario]:
    import agents.shell.process as process

    loaded: list[Scenario] = []
    real = process.load_scenario

    def load(*args: Any, **kwargs: Any) -> Scenario:
        loaded.append(real(*args, **kwargs))
        return loaded[-1]

    monkeypatch.setattr(process, "load_scenario", load)
    return loaded


@pytest.mark.timeout(30)
def test_a_target_loads_its_scenario_once_and_flies_it(monkeypatch: pytest.MonkeyPatch) -> None:
    import agents.target as target

    loaded = count_loads(monkeypatch)
    flown: list[tuple[AgentOptions, Scenario]] = []

    def fly(opts: AgentOptions, scenario: Scenario, *_: Any) -> int:
        flown.append((opts, scenario))
        return 0

    monkeypatch.setattr(target, "fly", fly)
    argv = ["--index", "1", "--scenario", "ring16", "--swarm", "s", "--estimator", "paper",
            "--connect", "tcp/127.0.0.1:1", "--mav-local-base", "15000", "--latency-stamps"]
    assert target.main(argv) == 0
    [(opts, scenario)] = flown
    assert len(loaded) == 1
    assert (opts.index, opts.bus.swarm, opts.bus.connect) == (1, "s", ("tcp/127.0.0.1:1",))
    assert opts.vehicle.mav_local_base == 15000 and opts.bus.network.latency_stamps
    assert scenario.network.estimator == "paper" and scenario.gains.estimator_order == 1


@pytest.mark.timeout(30)
def test_the_simulator_and_recorder_open_their_bus_on_the_scenario_they_loaded(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    import deploy.recording.recorder as recorder
    import sim_backend.swarm_sim as swarm_sim

    loaded = count_loads(monkeypatch)
    opened: list[tuple[BusOptions, Any]] = []

    def open_bus(opts: BusOptions, network: Any, *_: Any) -> Any:
        opened.append((opts, network))
        raise Stop("stand-in bus")

    argv = ["--scenario", "paper", "--link", "udp", "--swarm", "s"]
    for module, extra in ((swarm_sim, []), (recorder, ["--out", str(tmp_path)])):
        monkeypatch.setattr(module, "open_bus", open_bus)
        assert module.main([*argv, *extra]) == 2  # the named error, logged
    assert len(loaded) == 2 and len(opened) == 2  # once per process
    for (opts, network), scenario in zip(opened, loaded, strict=True):
        assert opts.swarm == "s" and network.link == "udp" != scenario.network.link


def test_network_faults_reach_a_namespaced_run_and_hosts_once(tmp_path: Path) -> None:
    part, kill = "40:partition:1,2|3,4:15", "3:kill:follower-1"
    first = run_options("--netns", "--fault", part, "--fault", kill)
    assert first.launch.faults == (kill,) and first.launch.network.net_faults == (part,)
    argv = netns_run.inner_argv(first.launch, tmp_path / "out", "sw", 60.0)
    again = RunOptions.from_namespace(build_parser(argv).parse_args(argv))
    assert again.launch.faults == (kill,) and again.launch.network.net_faults == (part,)
    argv = namespaced_hosts.inner_argv(first.launch, tmp_path, 60.0)
    host = HostOptions.from_namespace(build_parser(argv).parse_args(argv))
    assert host.launch.faults == (kill,) and host.launch.network.net_faults == (part,)
