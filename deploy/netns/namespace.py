"""`enclose run --netns`: the whole run in its own network namespace, with real packet loss.

This kernel has no netem, but nftables works inside a namespace: a rule on the *input*
hook of the namespace's `lo` drops a random share of every packet crossing loopback
(on the output hook UDP senders would get EPERM instead of a silent loss).  Zenoh's own
TCP or UDP links then see real loss, retransmits and all.  Only the network is
namespaced (`ip netns exec`), so the run directory is the caller's, as usual.

MAVLink between each
follower and its simulated autopilot is exempt: on a real drone that link is on board.
The namespace is named `enclose-<pid of the launcher>`; it is removed (and its nft
table with it) whatever happens, and one left by a crashed launcher whose PID is gone
is removed at the next start.

This module makes, watches and removes namespaces (also for `--hosts`:
deploy.hosts.namespaced_hosts); the run inside one, and its netns.json, is deploy.netns.netns_run.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from deploy.launch.ports import PX4_SITL_BASES
from deploy.procs.pids import identify, is_alive, signal_same
from errors import DeployError

log = logging.getLogger("enclose.netns")
PREFIX = "enclose-"
TABLE = "enclose_loss"
_OURS = re.compile(r"^enclose-(\d+)(?:-[a-z0-9]+)?$")
_TOOL_S = 15.0
STOP_GRACE_S = 5.0
# The autopilot link (MAVLink) is each drone's own, not the swarm's network: left lossless.
# In a fresh namespace every port is free, so the inner launcher takes PX4 SITL's blocks.
MAVLINK_PORTS = range(min(PX4_SITL_BASES), max(PX4_SITL_BASES) + 100)


def unavailable() -> str | None:
    """Why a namespace cannot be made here, or None (cheap: no namespace is created)."""
    if os.geteuid() != 0:
        return "needs root (network namespaces and nftables)"
    for tool, package in (("ip", "iproute2"), ("nft", "nftables")):
        if shutil.which(tool) is None:
            return f"`{tool}` not found (apt-get install {package})"
    return None


def install_tools() -> None:
    """Install iproute2 and nftables on first use of --netns (the main job does not need
    them, so set-up does not install them); as root with apt-get only, else a clear error."""
    missing = [pkg for tool, pkg in (("ip", "iproute2"), ("nft", "nftables"))
               if shutil.which(tool) is None]
    if not missing or os.geteuid() != 0 or shutil.which("apt-get") is None:
        return  # `unavailable` then says what is wrong
    log.warning("--netns needs %s: installing (apt-get, once)", " and ".join(missing))
    try:
        done = subprocess.run(["apt-get", "install", "-y", "-q", *missing], capture_output=True,
                              text=True, timeout=600, check=False,
                              env={**os.environ, "DEBIAN_FRONTEND": "noninteractive"})
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise DeployError(f"--netns: installing {' '.join(missing)} failed: {exc}") from exc
    if done.returncode != 0:
        raise DeployError(f"--netns: apt-get install {' '.join(missing)} failed: "
                          f"{done.stderr.strip()[-300:]}")


def probe() -> str | None:
    """Like `unavailable`, but also creates and removes a namespace with the table."""
    reason = unavailable()
    if reason is None:
        try:
            with lossy_namespace(0.0, name=f"{PREFIX}{os.getpid()}-probe"):
                pass
        except DeployError as exc:
            return str(exc)
    return reason


def _tool(argv: Sequence[str], stdin: str | None = None) -> str:
    try:
        done = subprocess.run(list(argv), input=stdin, capture_output=True, text=True,
                              timeout=_TOOL_S, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise DeployError(f"{' '.join(argv)}: {exc}") from exc
    if done.returncode != 0:
        raise DeployError(f"{' '.join(argv)} failed: {done.stderr.strip() or done.returncode}")
    return done.stdout


def namespaces() -> list[str]:
    """Names of the existing network namespaces (`ip netns list`)."""
    return [line.split()[0] for line in _tool(["ip", "netns", "list"]).splitlines() if line]


def nft_ruleset(loss: float, exempt_udp: range | None = MAVLINK_PORTS) -> str:
    """An inet table whose input chain counts loopback packets and drops `loss` of them,
    except UDP to or from `exempt_udp`."""
    if not 0.0 <= loss < 1.0:
        raise DeployError(f"--os-loss must be in [0, 1), got {loss}")
    per_10k = round(loss * 10000)
    rules = [f"udp {d} {exempt_udp.start}-{exempt_udp.stop - 1} accept"
             for d in ("dport", "sport") if exempt_udp is not None]
    rules.append('iifname "lo" counter')
    if per_10k:
        rules.append(f'iifname "lo" numgen random mod 10000 < {per_10k} counter drop')
    body = "".join(f"    {r}\n" for r in rules)
    return (f"table inet {TABLE} {{\n  chain input {{\n"
            f"    type filter hook input priority 0; policy accept;\n{body}  }}\n}}\n")


@dataclass(frozen=True)
class Namespace:
    name: str
    loss: float

    def exec_argv(self, argv: Sequence[str]) -> list[str]:
        return ["ip", "netns", "exec", self.name, *argv]

    def pids(self) -> list[int]:
        return [int(p) for p in _tool(["ip", "netns", "pids", self.name]).split()]

    def counters(self) -> dict[str, int]:
        """Packets seen on `lo` and dropped by the table so far."""
        table = json.loads(_tool(self.exec_argv(["nft", "-j", "list", "table", "inet", TABLE])))
        counts = [e["counter"]["packets"] for item in table["nftables"] if "rule" in item
                  for e in item["rule"]["expr"] if isinstance(e, dict) and "counter" in e]
        return {"packets_seen": counts[0], "packets_dropped": sum(counts[1:])}


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _stop_inside(ns: Namespace) -> None:
    """Whatever still runs in the namespace was started by this run: SIGTERM, then SIGKILL,
    each only to the process listed (deploy.procs.pids: one that exits meanwhile frees its PID)."""
    procs = [identify(pid) for pid in ns.pids()]
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for ident in procs:
            signal_same(ident, sig)
        deadline = time.monotonic() + STOP_GRACE_S
        while procs and time.monotonic() < deadline:
            time.sleep(0.05)
            procs = [p for p in procs if is_alive(p)]
        if not procs:
            return
        log.warning("namespace %s: %d processes ignored SIGTERM; killing them", ns.name,
                    len(procs))


def destroy(name: str) -> None:
    """Stop what runs in namespace `name`, drop its table, remove it; tolerant of each step."""
    ns = Namespace(name, 0.0)
    for step in (lambda: _stop_inside(ns),
                 lambda: _tool(ns.exec_argv(["nft", "delete", "table", "inet", TABLE]))):
        with contextlib.suppress(DeployError):
            step()
    _tool(["ip", "netns", "delete", name])


def clean_stale() -> list[str]:
    """Remove the namespaces of earlier launchers whose PID is gone; their names."""
    stale = [n for n in namespaces()
             if (m := _OURS.match(n)) is not None and not _pid_alive(int(m.group(1)))]
    for name in stale:
        log.warning("removing namespace %s left by a launcher that is gone", name)
        with contextlib.suppress(DeployError):
            destroy(name)
    return stale


def _fresh_name() -> str:
    taken, base = set(namespaces()), f"{PREFIX}{os.getpid()}"
    return next(n for n in (base, *(f"{base}-{k}" for k in range(1, 1000))) if n not in taken)


@contextlib.contextmanager
def lossy_namespace(loss: float, name: str | None = None) -> Iterator[Namespace]:
    """A fresh namespace with `lo` up and `loss` of its loopback packets dropped;
    removed on exit, also when the body raises or is interrupted."""
    install_tools()
    reason = unavailable()
    if reason is not None:
        raise DeployError(f"--netns {reason}")
    ruleset = nft_ruleset(loss)
    clean_stale()
    ns = Namespace(name or _fresh_name(), loss)
    _tool(["ip", "netns", "add", ns.name])  # fails on a taken name: never remove another's
    try:
        _tool(["ip", "-n", ns.name, "link", "set", "lo", "up"])
        _tool(ns.exec_argv(["nft", "-f", "-"]), stdin=ruleset)
        log.info("network namespace %s: loopback drops %.1f %% of packets", ns.name, 100 * loss)
        yield ns
    finally:
        destroy(ns.name)
