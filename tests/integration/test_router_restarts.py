"""Host routers restarted one after another: every client hears every other one again.

Three `deploy.hosts.router` processes on loopback, linked as a deployment links them
(`Deployment.router_links`), two client sessions behind each.  Zenoh 1.10's routers in a
mesh lost a restarted router's routes to one of the others almost every time; this is
the test that tells whether the deployment's topology heals.
"""

from __future__ import annotations

import contextlib
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from deploy.hosts.deployment import Deployment, HostSpec
from deploy.launch.ports import free_tcp_port
from tests.integration.runs import wait_for
from transport.bus import Subscription
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

pytestmark = pytest.mark.integration
REPO = Path(__file__).resolve().parents[2]
N_HOSTS = 3


def _deployment() -> Deployment:
    hosts = tuple(HostSpec(f"h{k}", "127.0.0.1", (), router_port=free_tcp_port())
                  for k in range(N_HOSTS))
    return Deployment("restarts", "paper", hosts)


class _Routers:
    def __init__(self, dep: Deployment, logs: Path) -> None:
        self.dep, self.logs = dep, logs
        self.procs: dict[int, subprocess.Popen[bytes]] = {}

    def start(self, k: int) -> None:
        argv = [sys.executable, "-m", "deploy.hosts.router", *self.dep.router_argv(k, secure=False)]
        with (self.logs / f"router-{k}.log").open("ab") as log:
            self.procs[k] = subprocess.Popen(argv, cwd=REPO, stdout=log, stderr=log)

    def restart(self, k: int) -> None:
        proc = self.procs[k]
        proc.send_signal(signal.SIGTERM)  # as the launcher's restart fault: a clean stop
        proc.wait(20)
        self.start(k)

    def kill_all(self) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)


@contextlib.contextmanager
def _routers(dep: Deployment, logs: Path) -> Iterator[_Routers]:
    routers = _Routers(dep, logs)
    try:
        for k in range(N_HOSTS):
            routers.start(k)
        yield routers
    finally:
        routers.kill_all()


class _Clients:
    """Two client sessions per host; `heard` is who heard whom since the last `forget`."""

    def __init__(self, dep: Deployment, stack: contextlib.ExitStack) -> None:
        self.names = [f"c{k}{i}" for k in range(N_HOSTS) for i in range(2)]
        self.buses: dict[str, ZenohBus] = {}
        self.subs: dict[str, Subscription] = {}
        for name in self.names:
            endpoint = dep.router_endpoint(int(name[1]), secure=False)
            bus = stack.enter_context(ZenohBus(ZenohConfig(mode="client", connect=(endpoint,))))
            self.buses[name] = bus
            self.subs[name] = bus.subscribe("restarts/**")
        self.heard: dict[str, set[str]] = {}

    def forget(self) -> None:
        for sub in self.subs.values():
            sub.drain()
        self.heard = {name: set() for name in self.names}

    def all_heard(self) -> bool:
        for name, bus in self.buses.items():
            bus.publish(f"restarts/{name}", b"x" * 64)
        for name, sub in self.subs.items():
            self.heard[name].update(r.key.rsplit("/", 1)[1] for r in sub.drain())
        return all(self.heard[n] >= set(self.names) - {n} for n in self.names)

    def deaf(self) -> dict[str, list[str]]:
        missing = {n: sorted(set(self.names) - {n} - self.heard[n]) for n in self.names}
        return {n: m for n, m in missing.items() if m}


@pytest.mark.timeout(240)
def test_every_client_hears_every_other_after_each_router_restart(tmp_path: Path) -> None:
    dep = _deployment()
    with _routers(dep, tmp_path) as routers, contextlib.ExitStack() as stack:
        clients = _Clients(dep, stack)
        clients.forget()
        wait_for(clients.all_heard, 30, "every client hearing every other one at the start")
        for k in (2, 1, 2, 0, 2, 1):
            routers.restart(k)
            clients.forget()
            try:
                wait_for(clients.all_heard, 30, f"every client hearing every other one "
                         f"after router-{k} restarted")
            except AssertionError as exc:
                raise AssertionError(f"{exc}; still deaf: {clients.deaf()}") from None
