"""Cost of security, on vs off: Zenoh state round trip (mTLS + ACL) and MAVLink round trip
(signing + verification), latency p50/p99 and CPU per round trip.

    python bench/bench_security.py [--n 2000]

1. Zenoh: an echo peer (this script with --echo, its own process) bounces a FollowerState
   from follower 0's key to follower 1's; plain tcp vs tls with per-run certificates and the
   swarm's access_control rules (the echo holds follower-1's certificate, we follower-0's).
2. MAVLink: a COMMAND_LONG (REQUEST_MESSAGE) over UDP to a simulated vehicle, stepped in
   this process, and its COMMAND_ACK back; unsigned vs signed + verified by the vehicle.
CPU: process CPU seconds (user+sys, both ends for Zenoh) per round trip.  Short runs only.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from agents.mavlink.signing import signing_timestamp
from agents.mavlink.wire import new_codec, sign_outgoing
from agents.mavlink.wire_decode import decode_datagram
from agents.scenario.model import HomeConfig, VehicleConfig
from deploy.launch.ports import free_tcp_port
from deploy.report.cpu_load import process_cpu_s
from sim_backend.runtime import SimConfig, Simulator, grid_spawn_ned
from transport.codec import encode
from transport.credentials import Identity, identity_file, make_credentials
from transport.key_exprs import SwarmKeys
from transport.messages import FollowerState, Stamper
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

KEYS = SwarmKeys("benchsec")
KEY = os.urandom(32)


def cpu_s(pid: int | None = None) -> float:
    if pid is None:
        t = os.times()
        return t.user + t.system
    used = process_cpu_s(pid)
    if used is None:
        raise RuntimeError(f"process {pid} is gone")
    return used


def zenoh_cfg(creds: str | None, name: str, **kw: object) -> ZenohConfig:
    ident = None if creds is None else Identity.load(identity_file(Path(creds), name))
    return ZenohConfig(identity=ident, **kw)  # type: ignore[arg-type]


def echo(endpoint: str, creds: str | None) -> int:
    stop: list[int] = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    with ZenohBus(zenoh_cfg(creds, "follower-1", listen=(endpoint,))) as bus:
        sub = bus.subscribe(KEYS.follower_state(0))
        pub = bus.declare_publisher(KEYS.follower_state(1))
        bus.declare_token(KEYS.alive("follower", 1))
        deadline = time.monotonic() + 60
        while not stop and time.monotonic() < deadline:
            for rec in sub.drain():
                pub.put(rec.payload)
            time.sleep(0)
    return 0


def zenoh_rtt(n: int, creds: str | None) -> tuple[list[float], float]:
    endpoint = f"{'tls' if creds else 'tcp'}/127.0.0.1:{free_tcp_port()}"
    cmd = [sys.executable, __file__, "--echo", endpoint] + (["--creds", creds] if creds else [])
    proc = subprocess.Popen(cmd)
    try:
        with ZenohBus(zenoh_cfg(creds, "follower-0", connect=(endpoint,))) as bus:
            alive = bus.watch_alive(KEYS.all_alive())
            deadline = time.monotonic() + 20
            while not alive.poll() and time.monotonic() < deadline:
                time.sleep(0.01)
            sub, pub = bus.subscribe(KEYS.follower_state(1)), bus.declare_publisher(
                KEYS.follower_state(0))
            stamper, rtts = Stamper("follower-0"), []
            state = FollowerState(stamper.header(), 0, (1.0, 2.0), (0.1, 0.2),
                                  (10.0, -20.0), (0.5, 0.6), (0.7, 0.8), time.time(),
                                  {"phi_m": (0.3, 0.4)})
            payload = encode(state)
            c0 = cpu_s() + cpu_s(proc.pid)
            for k in range(n + 50):
                t0 = time.perf_counter()
                pub.put(payload)
                while not sub.drain():
                    time.sleep(0)
                if k >= 50:
                    rtts.append(time.perf_counter() - t0)
            cpu = (cpu_s() + cpu_s(proc.pid) - c0) / (n + 50)
    finally:
        proc.terminate()
        proc.wait(10)
    return rtts, cpu


def mavlink_rtt(n: int, signed: bool) -> tuple[list[float], float]:
    sim = Simulator(grid_spawn_ned(1), VehicleConfig(), HomeConfig(),
                    SimConfig(listen_base_port=0, send_base_port=9,
                              signing_key=KEY if signed else None))
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    client.settimeout(1.0)
    gcs, rx = new_codec(245, 191), new_codec(250, 0)
    if signed:
        sign_outgoing(gcs, KEY, 0, signing_timestamp(time.time()))
    vehicle = ("127.0.0.1", sim.endpoints[0].sock.getsockname()[1])
    rtts = []
    c0 = cpu_s()
    try:
        for k in range(n + 50):
            t0 = time.perf_counter()
            client.sendto(gcs.command_long_encode(1, 1, 512, 0, 0, 0, 0, 0, 0, 0, 0).pack(gcs),
                          vehicle)
            sim.receive_until(-1.0)
            while not any(m.get_type() == "COMMAND_ACK" for m in
                          decode_datagram(rx, client.recvfrom(65535)[0]).messages):
                pass
            if k >= 50:
                rtts.append(time.perf_counter() - t0)
        cpu = (cpu_s() - c0) / (n + 50)
        assert sim.counters["commands"] == n + 50, sim.counters
    finally:
        client.close()
        sim.close()
    return rtts, cpu


def show(label: str, rtts: list[float], cpu: float) -> None:
    rtts = sorted(rtts)
    p50, p99 = statistics.median(rtts), rtts[int(0.99 * len(rtts))]
    print(f"{label:34s} n={len(rtts)}: p50 {p50 * 1e6:6.0f} us  p99 {p99 * 1e6:6.0f} us  "
          f"CPU {cpu * 1e6:5.0f} us/round trip")


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--n", type=int, default=2000)
    p.add_argument("--echo", default=None)
    p.add_argument("--creds", default=None)
    args = p.parse_args()
    if args.echo:
        return echo(args.echo, args.creds)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory() as tmp:
        creds = str(make_credentials(Path(tmp) / "c", KEYS, 2, 0))
        for label, c in (("zenoh state rtt, tcp (insecure)", None),
                         ("zenoh state rtt, mTLS + ACL", creds)):
            show(label, *zenoh_rtt(args.n, c))
    for label, signed in (("mavlink command rtt, unsigned", False),
                          ("mavlink command rtt, signed", True)):
        show(label, *mavlink_rtt(args.n, signed))
    return 0


if __name__ == "__main__":
    sys.exit(main())
