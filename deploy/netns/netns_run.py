"""`enclose run --netns` itself: its flags, and the whole run as an inner `enclose run`
in a lossy namespace (deploy.netns.namespace), reported in RUN_DIR/netns.json.

Apart from the namespace machinery (deploy.netns.namespace), which `--hosts`
(deploy.hosts.namespaced_hosts) shares and which knows nothing of a run's command line or its files.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import signal
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from types import FrameType

from agents.shell.law_args import law_overrides
from agents.shell.lifeline import launcher_env
from agents.shell.network_args import network_overrides
from deploy.launch.launch_options import LaunchOptions
from deploy.netns.namespace import MAVLINK_PORTS, lossy_namespace
from errors import DeployError

log = logging.getLogger("enclose.netns")


def add_netns_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("OS-level network (root, Linux network namespace + nftables)")
    g.add_argument("--netns", action="store_true",
                   help="run everything in a fresh network namespace, removed afterwards")
    g.add_argument("--os-loss", type=float, default=None, metavar="P",
                   help="fraction of loopback packets the kernel drops (needs --netns)")


@dataclass(frozen=True)
class NetnsOptions:
    """`--netns [--os-loss P]`: the run in a namespace whose loopback loses `os_loss`."""

    os_loss: float = 0.0

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> NetnsOptions | None:
        """None without --netns; --os-loss alone is an error."""
        if args.os_loss is not None and not args.netns:
            raise DeployError("--os-loss needs --netns (it drops packets inside the namespace)")
        return cls(args.os_loss or 0.0) if args.netns else None


def inner_argv(opts: LaunchOptions, out: Path, swarm: str, duration_s: float) -> list[str]:
    """`enclose run` as given, without --netns, for the launcher inside the namespace."""
    scen = opts.scenario_ref() if opts.scenario else None
    argv = ["-v"] * opts.verbose + ["run", *([scen] if scen else [])]
    argv += ["--duration", repr(duration_s), "--out", str(out), "--swarm", swarm,
             *opts.supervision_argv()]
    if opts.zenoh_config:
        argv += ["--zenoh-config", str(Path(opts.zenoh_config).resolve())]
    # The namespace's loopback is not this machine's: a live view there could not be opened.
    argv.append("--no-live")
    if opts.json:
        argv.append("--json")
    return argv + network_overrides(opts.network) + law_overrides(opts.law)


def run_forwarding_signals(argv: Sequence[str]) -> int:
    """Run `argv` in its own session (a terminal's Ctrl-C reaches only us, once) and pass
    SIGINT/SIGTERM on to it; its exit code, 128+N when killed by signal N.  It dies with
    us (agents.shell.lifeline), and its processes with it."""
    proc = subprocess.Popen(list(argv), stdin=subprocess.DEVNULL, start_new_session=True,
                            env={**os.environ, **launcher_env()})

    def forward(signum: int, frame: FrameType | None) -> None:
        with contextlib.suppress(ProcessLookupError):
            proc.send_signal(signum)

    previous = {s: signal.signal(s, forward) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        code = proc.wait()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(60.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    return code if code >= 0 else 128 - code


def _mavlink_exempt(out: Path) -> bool | None:
    """Whether the run's MAVLink ports were the lossless ones (None: run never started)."""
    try:
        launch = json.loads((out / "launch.json").read_text())
        bases = (int(launch["vehicle_base_port"]), int(launch["adapter_base_port"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None
    exempt = all(b in MAVLINK_PORTS for b in bases)
    if not exempt:
        log.warning("MAVLink used ports %s, outside the lossless %s", bases, MAVLINK_PORTS)
    return exempt


def run_in_namespace(netns: NetnsOptions, opts: LaunchOptions, out: Path, swarm: str,
                     duration_s: float) -> int:
    """The whole `enclose run` inside a lossy namespace; writes RUN_DIR/netns.json."""
    loss = netns.os_loss
    out.mkdir(parents=True, exist_ok=True)
    with lossy_namespace(loss) as ns:
        argv = ns.exec_argv([sys.executable, "-m", "deploy.cli",
                             *inner_argv(opts, out, swarm, duration_s)])
        code = run_forwarding_signals(argv)
        report: dict[str, object] = {"namespace": ns.name, "os_loss": loss, "exit_code": code}
        with contextlib.suppress(DeployError, ValueError, KeyError, IndexError):
            report.update(ns.counters())
    report["mavlink_lossless"] = _mavlink_exempt(out)
    seen, dropped = report.get("packets_seen"), report.get("packets_dropped")
    if isinstance(seen, int) and isinstance(dropped, int) and seen:
        report["measured_loss"] = dropped / seen
        log.info("namespace %s removed; the kernel dropped %d of %d loopback packets (%.1f %%)",
                 ns.name, dropped, seen, 100.0 * dropped / seen)
    (out / "netns.json").write_text(json.dumps(report, indent=2) + "\n")
    return code
