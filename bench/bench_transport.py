"""Transport benchmark: FollowerState round trip and BLOCK vs DROP loss, two processes.

    python bench/bench_transport.py [--n-rtt 2000] [--n-flood 20000]

Spawns an echo peer (this script with --echo) on 127.0.0.1, then
1. ping-pong: encode a FollowerState, publish, the echo decodes and re-encodes
   it on another key, decode the reply; round trip p50/p99 (default config, then
   `lowlatency`);
2. flood: publish n FollowerStates back to back with congestion BLOCK, then
   DROP; the echo counts what arrives (its ring is large enough to drop nothing).
Runs in well under a minute.  Prints figures; touches nothing else.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import signal
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Callable

from transport.bus import Congestion
from transport.codec import encode
from transport.decoder import Decoder
from transport.key_exprs import SwarmKeys
from transport.messages import FollowerState, ProcessStatus, Stamper
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig, loopback_endpoint

KEYS = SwarmKeys(f"bench{os.getpid()}")
PING, PONG = KEYS.follower_state(0), KEYS.follower_state(1)
# Measured: a pure busy loop on both ends gave a round-trip p99 of 4-8 ms on 2 cores;
# yielding with sleep(0) between polls gives p99 < 1 ms.
IDLE_S = 0.0
FLOOD = {Congestion.BLOCK: KEYS.follower_state(2), Congestion.DROP: KEYS.follower_state(3)}


def echo(port: int, swarm: str, lowlatency: bool) -> int:
    keys = SwarmKeys(swarm)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    cfg = ZenohConfig(listen=(loopback_endpoint(port),), lowlatency=lowlatency)
    pong_stamper, status_stamper, decoder = Stamper("echo"), Stamper("echo"), Decoder()
    counts = {"block": 0, "drop": 0}
    deadline, next_status = time.monotonic() + 50.0, 0.0
    with ZenohBus(cfg) as bus:
        ping = bus.subscribe(keys.follower_state(0))
        floods = [bus.subscribe(keys.follower_state(k), capacity=200_000) for k in (2, 3)]
        pong = bus.declare_publisher(keys.follower_state(1))
        status = bus.declare_publisher(keys.status("echo", 0))
        bus.declare_token(keys.alive("echo", 0))
        while not stop and time.monotonic() < deadline:
            pings = decoder.drain(ping)
            if not pings:
                time.sleep(IDLE_S)
            for inbound in pings:
                msg = inbound.message
                if not isinstance(msg, FollowerState):
                    continue
                pong.put(encode(dataclasses.replace(msg, header=pong_stamper.header(), index=1)))
            for name, sub in zip(("block", "drop"), floods, strict=True):
                counts[name] += len(sub.drain())
            if time.monotonic() > next_status:
                next_status = time.monotonic() + 0.05
                msg = ProcessStatus(status_stamper.header(), "echo", 0, "running", counts)
                status.put(encode(msg))
    return 0


def wait_for(cond: Callable[[], bool], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            raise SystemExit("bench: peer did not come up")
        time.sleep(0.001)


def sample_state(stamper: Stamper) -> FollowerState:
    return FollowerState(stamper.header(), 0, (1.0, 2.0), (0.1, 0.2), (10.0, -20.0),
                         (0.5, 0.6), (0.7, 0.8), time.time(), {"phi_m": (0.3, 0.4)})


def ping_pong(bus: ZenohBus, n: int) -> list[float]:
    sub, pub = bus.subscribe(PONG), bus.declare_publisher(PING)
    wait_for(pub.matched, 10)
    stamper, decoder, rtts = Stamper("bench"), Decoder(), []
    for k in range(n + 50):
        t0 = time.perf_counter()
        pub.put(encode(sample_state(stamper)))
        while not decoder.drain(sub):
            time.sleep(IDLE_S)
        if k >= 50:  # warm-up
            rtts.append(time.perf_counter() - t0)
    return rtts


def flood(bus: ZenohBus, n: int, congestion: Congestion) -> tuple[float, float]:
    """(publish rate Hz, fraction lost) for n back-to-back puts."""
    pub = bus.declare_publisher(FLOOD[congestion], congestion)
    status = bus.subscribe(KEYS.status("echo", 0))
    wait_for(pub.matched, 10)
    stamper, payloads = Stamper("bench"), []
    payloads = [encode(sample_state(stamper)) for _ in range(n)]
    t0 = time.perf_counter()
    for p in payloads:
        pub.put(p)
    rate = n / (time.perf_counter() - t0)
    name, decoder, got, stable_since = congestion.value, Decoder(), -1, time.monotonic()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and time.monotonic() - stable_since < 0.5:
        for inbound in decoder.drain(status):
            assert isinstance(inbound.message, ProcessStatus)
            now = inbound.message.counters[name]
            if now != got:
                got, stable_since = now, time.monotonic()
        time.sleep(0.01)
    status.close()
    return rate, 1.0 - got / n


def run(lowlatency: bool, n_rtt: int, n_flood: int) -> None:
    port = _free_port()
    cmd = [sys.executable, __file__, "--echo", str(port), "--swarm", KEYS.swarm]
    proc = subprocess.Popen(cmd + (["--lowlatency"] if lowlatency else []))
    try:
        cfg = ZenohConfig(connect=(loopback_endpoint(port),), lowlatency=lowlatency)
        with ZenohBus(cfg) as bus:
            alive = bus.watch_alive(KEYS.all_alive())
            wait_for(lambda: bool(alive.poll()), 20)
            rtts = sorted(ping_pong(bus, n_rtt))
            p50, p99 = statistics.median(rtts), rtts[int(0.99 * len(rtts))]
            label = "lowlatency" if lowlatency else "default"
            size = len(encode(sample_state(Stamper("bench"))))
            print(f"rtt[{label}] FollowerState {size} B, n={len(rtts)}: "
                  f"p50 {p50 * 1e6:.0f} us, p99 {p99 * 1e6:.0f} us")
            if n_flood:
                for congestion in (Congestion.BLOCK, Congestion.DROP):
                    rate, lost = flood(bus, n_flood, congestion)
                    print(f"flood[{label}] {congestion.name}: n={n_flood}, "
                          f"put rate {rate:,.0f}/s, lost {100 * lost:.1f} %")
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n-rtt", type=int, default=2000)
    parser.add_argument("--n-flood", type=int, default=20000)
    parser.add_argument("--echo", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--swarm", help=argparse.SUPPRESS)
    parser.add_argument("--lowlatency", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.echo is not None:
        return echo(args.echo, args.swarm, args.lowlatency)
    t0 = time.monotonic()
    run(False, args.n_rtt, args.n_flood)
    run(True, args.n_rtt, args.n_flood)
    print(f"bench_transport done in {time.monotonic() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
