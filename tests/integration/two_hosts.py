"""Two hosts started as docs/multihost.md says, each a network namespace of this machine.

One deployment file (the docs' own, at the namespaces' addresses), `enclose keys OUT
--deployment FILE` once, then `enclose host FILE --host NAME --credentials OUT/NAME/` per
host, each its own process in its own namespace, the companion first, as in the docs.
The namespaces are the `--hosts` ones (deploy.hosts.namespaced_hosts.linked_namespaces: veth links
to a bridge in a hub namespace); they, and every process started here, are gone
afterwards whatever happens (by PID: the hosts, then what their run directories name).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import IO

from deploy.hosts.deployment import Deployment, load_deployment
from deploy.hosts.namespaced_hosts import linked_namespaces
from tests.integration.runs import kill_leftovers, wait_for

GROUND, COMPANION = "ground", "companion"
DEPLOYMENT = """\
swarm = "field-test"
scenario = "paper"                  # the same scenario on every host
[[hosts]]
name = "ground"                     # the laptop: simulator, launcher, recorder, targets
address = "10.77.0.1"
router_port = 7447
processes = ["launcher", "sim", "recorder", "target-0", "target-1"]
[[hosts]]
name = "companion"                  # e.g. a drone's companion computer
address = "10.77.0.2"
router_port = 7447
processes = ["follower-0", "follower-1", "follower-2", "follower-3"]
"""
STOP_S = 20.0
CHECKOUT = Path(__file__).resolve().parents[2]


@dataclass
class TwoHosts:
    """The hosts' namespaces and what was started in them."""

    root: Path  # the working directory both hosts run in (a checkout, on real hosts)
    netns: dict[str, str]
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)
    logs: dict[str, IO[bytes]] = field(default_factory=dict)

    def enclose(self, *argv: str) -> list[str]:
        return [sys.executable, "-m", "deploy.cli", *argv]

    def in_host(self, host: str, argv: Sequence[str]) -> list[str]:
        return ["ip", "netns", "exec", self.netns[host], *argv]

    def start_host(self, host: str, *extra: str) -> subprocess.Popen[bytes]:
        """`enclose host deployment.toml --host HOST --credentials creds/HOST/ ...` in the
        host's namespace, its output in HOST.log."""
        argv = self.enclose("host", "deployment.toml", "--host", host, "--credentials",
                            f"creds/{host}/", *extra)
        log = self.logs[host] = (self.root / f"{host}.log").open("wb")
        proc = self.procs[host] = subprocess.Popen(
            self.in_host(host, argv), cwd=self.root, stdout=log, stderr=subprocess.STDOUT)
        return proc

    def start(self, host: str, argv: Sequence[str], name: str) -> subprocess.Popen[bytes]:
        """Any other process in a host's namespace (by `name`, stopped with the hosts); the
        checkout's own modules (tests.*) importable."""
        log = self.logs[name] = (self.root / f"{name}.log").open("wb")
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(
            [str(CHECKOUT), *filter(None, [os.environ.get("PYTHONPATH")])])}
        proc = self.procs[name] = subprocess.Popen(
            self.in_host(host, argv), cwd=self.root, stdout=log, stderr=subprocess.STDOUT,
            env=env)
        return proc

    def wait_all(self, timeout_s: float) -> None:
        wait_for(lambda: all(p.poll() is not None for p in self.procs.values()), timeout_s,
                 f"{', '.join(self.procs)} to end")

    def output(self, name: str) -> str:
        return (self.root / f"{name}.log").read_text(errors="replace")

    def tracebacks(self) -> list[str]:
        """The files under root (hosts' outputs, every process log) showing a traceback."""
        return [str(p.relative_to(self.root)) for p in sorted(self.root.rglob("*.log"))
                if "Traceback (most recent call last)" in p.read_text(errors="replace")]

    def stop(self) -> None:
        """Ctrl-C to what still runs (a host stops its part cleanly), SIGKILL after
        STOP_S; then whatever the hosts' run directories name."""
        running = [p for p in self.procs.values() if p.poll() is None]
        for p in running:
            with contextlib.suppress(ProcessLookupError):
                os.kill(p.pid, signal.SIGINT)
        with contextlib.suppress(AssertionError):
            wait_for(lambda: all(p.poll() is not None for p in running), STOP_S,
                     "the hosts to stop")
        for p in running:
            if p.poll() is None:
                p.kill()
            p.wait(10)
        for log in self.logs.values():
            log.close()
        for pids in self.root.rglob("logs/pids.json"):
            kill_leftovers(pids.parent.parent)


def namespaced(dep: Deployment, prefix: str) -> Deployment:
    """`dep` with a namespace per host, for linked_namespaces only: the hosts themselves
    are given the file as written, without namespaces, as real hosts are."""
    hosts = tuple(replace(h, netns=f"{prefix}-{k}") for k, h in enumerate(dep.hosts))
    return replace(dep, hosts=hosts)


@contextlib.contextmanager
def two_hosts(root: Path) -> Iterator[TwoHosts]:
    """The deployment file and `enclose keys creds/ --deployment deployment.toml` in
    `root`, the hosts' namespaces linked; nothing started yet."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "deployment.toml").write_text(DEPLOYMENT)
    keys = subprocess.run([sys.executable, "-m", "deploy.cli", "keys", "creds/",
                           "--deployment", "deployment.toml"], cwd=root, capture_output=True,
                          text=True, timeout=120, check=False)
    assert keys.returncode == 0, keys.stdout + keys.stderr
    prefix = f"enclose-{os.getpid()}"
    dep = namespaced(load_deployment(root / "deployment.toml"), prefix)
    with linked_namespaces(dep, f"{prefix}-hub"):
        hosts = TwoHosts(root, {h.name: str(h.netns) for h in dep.hosts})
        try:
            yield hosts
        finally:
            hosts.stop()
