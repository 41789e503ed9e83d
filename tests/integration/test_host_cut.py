"""The nftables cut between two namespaced hosts (deploy.hosts.host_cut), on real namespaces:
TCP between the hosts stops at the cut and passes again at the heal, MAVLink's UDP and
the simulator's sensing link (TCP to the sensing port) pass throughout, the hosts' kernels
give up a connect after one SYN retry and a connection after 3 retransmits, and neither
the table nor a namespace is left behind."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

from agents.scenario.net_faults import parse_net_fault_flag
from deploy.hosts.deployment import Deployment, HostSpec
from deploy.hosts.host_cut import CUT_TABLE, HostCut
from deploy.hosts.namespaced_hosts import SYN_RETRIES, TCP_RETRIES, linked_namespaces, unavailable

pytestmark = pytest.mark.integration
REASON = unavailable()
TCP_PORT, SENSE_PORT, MAV_PORT = 7447, 7448, 14560
# TCP acceptors (the router's port, the sensing port) and a UDP echo on host 1, by PID.
SERVER = f"""
import socket, threading
def acceptor(port):
    t = socket.socket(); t.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    t.bind(("0.0.0.0", port)); t.listen(16)
    while True:
        c, _ = t.accept(); c.close()
u = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); u.bind(("0.0.0.0", {MAV_PORT}))
def echo():
    while True:
        data, peer = u.recvfrom(64); u.sendto(data, peer)
threading.Thread(target=echo, daemon=True).start()
threading.Thread(target=acceptor, args=({SENSE_PORT},), daemon=True).start()
print("ready", flush=True)
acceptor({TCP_PORT})
"""
CLIENT = """
import socket, sys
kind, port = sys.argv[1], int(sys.argv[2])
try:
    if kind == "tcp":
        socket.create_connection(("10.77.0.2", port), timeout=1.0).close()
    else:
        u = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); u.settimeout(1.0)
        u.sendto(b"x", ("10.77.0.2", port)); u.recvfrom(64)
except OSError:
    sys.exit(1)
"""


def reaches(ns: str, kind: str, port: int) -> bool:
    done = subprocess.run(["ip", "netns", "exec", ns, sys.executable, "-c", CLIENT, kind,
                           str(port)], capture_output=True, timeout=20, check=False)
    return done.returncode == 0


@contextlib.contextmanager
def server(ns: str) -> Iterator[None]:
    proc = subprocess.Popen(["ip", "netns", "exec", ns, sys.executable, "-c", SERVER],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        yield
    finally:
        proc.kill()
        proc.wait(10)


def kernel(ns: str, setting: str) -> int:
    done = subprocess.run(["ip", "netns", "exec", ns, "sysctl", "-n", f"net.ipv4.{setting}"],
                          capture_output=True, text=True, check=True)
    return int(done.stdout)


def namespaces() -> str:
    return subprocess.run(["ip", "netns", "list"], capture_output=True, text=True,
                          check=False).stdout


@pytest.mark.skipif(REASON is not None, reason=f"nftables cut between hosts: {REASON}")
@pytest.mark.timeout(120)
def test_a_partition_along_hosts_is_cut_by_nftables_and_healed() -> None:
    prefix = f"enclose-{os.getpid()}-cut"
    dep = Deployment("t", "paper", (
        HostSpec("h0", "10.77.0.1", ("launcher", "sim", "follower-0", "follower-1"),
                 netns=f"{prefix}-h0"),
        HostSpec("h1", "10.77.0.2", ("follower-2", "follower-3"), netns=f"{prefix}-h1")),
        cut_hub=f"{prefix}-hub")
    fault = parse_net_fault_flag("1:partition:1,2|3,4:2", 4)
    h0 = f"{prefix}-h0"
    with linked_namespaces(dep, f"{prefix}-hub"), server(f"{prefix}-h1"):
        assert kernel(h0, "tcp_syn_retries") == SYN_RETRIES
        assert kernel(h0, "tcp_retries2") == TCP_RETRIES
        cut = HostCut(f"{prefix}-hub", dep, (fault,), (range(14540, 14640),),
                      exempt_tcp=(SENSE_PORT,))
        cut.open()
        try:
            assert reaches(h0, "tcp", TCP_PORT)
            cut.check(1.5)  # inside the window
            assert cut.applied == {(0, 1), (1, 0)}
            assert not reaches(h0, "tcp", TCP_PORT)
            assert reaches(h0, "udp", MAV_PORT)  # the autopilot link is exempt
            assert reaches(h0, "tcp", SENSE_PORT)  # and so is the sensing link
            assert (cut.dropped() or 0) > 0
            cut.check(3.0)  # healed
            assert cut.applied == frozenset()
            deadline = time.monotonic() + 10.0
            while not reaches(h0, "tcp", TCP_PORT):
                assert time.monotonic() < deadline, "not reachable after the heal"
        finally:
            cut.close()
        tables = subprocess.run(["ip", "netns", "exec", f"{prefix}-hub", "nft", "list",
                                 "tables"], capture_output=True, text=True, check=True).stdout
        assert CUT_TABLE not in tables
    assert prefix not in namespaces()
