"""The peer mesh between real processes on 127.0.0.1: one TCP link a pair of peers.

Zenoh's default has both peers of a pair dial each other once gossip names them, and both
links stay; transport.zenoh_config asks that only the one of greater ZID dial.  Counted
from the kernel's own table of connections (/proc/net/tcp), by PID.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from collections import Counter
from collections.abc import Iterator
from itertools import combinations
from pathlib import Path

import pytest

from tests.integration.runs import wait_for
from tests.integration.test_transport_zenoh import free_port
from transport.zenoh_config import loopback_endpoint

pytestmark = pytest.mark.integration
REPO = Path(__file__).resolve().parents[2]
_ESTABLISHED = "01"


def _socket_inodes(pid: int) -> set[str]:
    inodes = set()
    fd_dir = Path(f"/proc/{pid}/fd")
    for fd in os.listdir(fd_dir):
        with contextlib.suppress(OSError):
            target = os.readlink(fd_dir / fd)
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    return inodes


def links(pids: list[int]) -> Counter[frozenset[int]]:
    """TCP connections between the processes `pids`, per unordered pair."""
    owner = {inode: pid for pid in pids for inode in _socket_inodes(pid)}
    ends = []  # (pid, local port, remote port) of every established socket of ours
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        fields = line.split()
        if fields[3] == _ESTABLISHED and fields[9] in owner:
            local, remote = (int(f.split(":")[1], 16) for f in fields[1:3])
            ends.append((owner[fields[9]], local, remote))
    by_port = {local: pid for pid, local, _ in ends}
    pairs: Counter[frozenset[int]] = Counter()
    for pid, local, remote in ends:
        other = by_port.get(remote)
        if other is not None and other != pid and local < remote:  # each connection once
            pairs[frozenset((pid, other))] += 1
    return pairs


@contextlib.contextmanager
def peers(n: int, swarm: str) -> Iterator[list[subprocess.Popen[bytes]]]:
    """`n` peers: the first listens on a known port, the others connect to it and gossip."""
    rendezvous = loopback_endpoint(free_port())
    procs: list[subprocess.Popen[bytes]] = []
    try:
        for i in range(n):
            argv = [sys.executable, "-m", "tests.integration.mesh_peer", "--swarm", swarm,
                    "--index", str(i), "--max-s", "80"]
            argv += (["--listen", rendezvous] if i == 0 else
                     ["--listen", loopback_endpoint(0), "--connect", rendezvous])
            procs.append(subprocess.Popen(argv, cwd=REPO))
        yield procs
    finally:
        for proc in procs:
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)


@pytest.mark.timeout(90)
def test_gossiping_peers_hold_one_link_a_pair() -> None:
    n = 5
    with peers(n, f"mesh{os.getpid()}") as procs:
        pids = [p.pid for p in procs]
        every_pair = {frozenset(pair) for pair in combinations(pids, 2)}
        wait_for(lambda: set(links(pids)) == every_pair, 60, "every pair of peers linked")
        counts = links(pids)
        assert set(counts) == every_pair
        assert max(counts.values()) == 1, f"pairs with two links: {counts}"
        for proc in procs:
            proc.send_signal(signal.SIGTERM)
        assert [proc.wait(timeout=20) for proc in procs] == [0] * n
