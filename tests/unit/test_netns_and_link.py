"""Link protocol endpoints and the --netns plumbing that needs no root (no namespace made)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from deploy.commands.run import RunOptions
from deploy.launch.ports import rendezvous_endpoint
from deploy.netns import namespace as netns
from deploy.netns import netns_run
from errors import ConfigError, DeployError
from transport.zenoh_config import ZenohConfig, build_zenoh_config, loopback_endpoint


def run_args(*argv: str) -> argparse.Namespace:
    from deploy.cli import build_parser

    return build_parser().parse_args(["run", *argv])


def test_default_listen_endpoint_follows_the_link_protocol() -> None:
    for link in ("tcp", "udp"):
        cfg = build_zenoh_config(ZenohConfig(link=link))
        assert json.loads(cfg.get_json("listen/endpoints")) == [f"{link}/127.0.0.1:0"]
    with pytest.raises(ConfigError):
        ZenohConfig(link="quic")
    with pytest.raises(ConfigError):
        loopback_endpoint(7447, "serial")


@pytest.mark.realtime
def test_rendezvous_endpoint_is_of_the_link_protocol_and_avoids_the_mavlink_blocks() -> None:
    assert rendezvous_endpoint("tcp").startswith("tcp/127.0.0.1:")
    every_port = [range(1, 65536)]
    with pytest.raises(DeployError):
        rendezvous_endpoint("udp", avoid=every_port)
    port = int(rendezvous_endpoint("udp", avoid=[range(1, 1024)]).rsplit(":", 1)[1])
    assert port >= 1024


def test_os_loss_without_netns_is_an_error_and_netns_is_opt_in() -> None:
    read = netns_run.NetnsOptions.from_namespace
    with pytest.raises(DeployError, match="--netns"):
        read(run_args("--os-loss", "0.1"))
    assert read(run_args("--netns", "--os-loss", "0.1")) == netns_run.NetnsOptions(0.1)
    assert read(run_args("--netns")) == netns_run.NetnsOptions(0.0)
    assert read(run_args()) is None


def test_ruleset_drops_the_fraction_on_the_input_hook_and_spares_mavlink() -> None:
    rules = netns.nft_ruleset(0.125)
    assert "hook input" in rules and "numgen random mod 10000 < 1250 counter drop" in rules
    assert "udp dport 14540-14679 accept" in rules
    assert "drop" not in netns.nft_ruleset(0.0)
    for bad in (-0.1, 1.0):
        with pytest.raises(DeployError):
            netns.nft_ruleset(bad)


def test_inner_command_is_the_same_run_without_netns(tmp_path: Path) -> None:
    scen = tmp_path / "s.toml"
    args = run_args(str(scen), "--netns", "--os-loss", "0.1", "--link", "udp", "--loss", "0.02")
    opts = RunOptions.from_namespace(args)
    argv = netns_run.inner_argv(opts.launch, tmp_path / "out", "sw", 30.0)
    assert argv[:2] == ["run", str(scen.resolve())]
    assert "--netns" not in argv and "--os-loss" not in argv
    assert argv[argv.index("--link") + 1] == "udp"
    assert argv[argv.index("--loss") + 1] == "0.02"
    assert argv[argv.index("--out") + 1] == str(tmp_path / "out")
    assert argv[argv.index("--duration") + 1] == "30.0"


@pytest.mark.realtime
def test_missing_tools_or_root_are_named(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(netns.os, "geteuid", lambda: 1000)
    assert "root" in (netns.unavailable() or "")
    monkeypatch.setattr(netns.os, "geteuid", lambda: 0)
    monkeypatch.setattr(netns.shutil, "which", lambda tool: None if tool == "nft" else tool)
    assert "nftables" in (netns.unavailable() or "")
    with pytest.raises(DeployError, match="nftables"), netns.lossy_namespace(0.1):
        pass
