"""What a consumer that stops reading costs a publisher: put() time under BLOCK and DROP.

    python bench/bench_slow_consumer.py [--seconds 20] [--hz 50] [--bytes 300] \
        [--drop-wait-us N]

Three processes on 127.0.0.1: this one publishes `--bytes` samples at `--hz` (the slow
consumer's socket buffers take megabytes before its queue fills: 1 MB/s fills them in
seconds, a swarm's whole key space in tens of seconds);
a reader drains a ring (a well-behaved neighbour) and counts what arrives; a slow
consumer subscribes with a callback that sleeps 1 s per sample on Zenoh's receiving
thread, so its link's queue fills.  For BLOCK then DROP, prints put() p50 / p99 / max and
the share of periods the put overran, with and without the slow consumer, and what the
reader got.  `--drop-wait-us` sets Zenoh's `wait_before_drop` (default: Zenoh's 1000).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

import zenoh

from transport.bus import Congestion
from transport.key_exprs import SwarmKeys
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig, build_zenoh_config, loopback_endpoint

KEYS = SwarmKeys(f"slow{os.getpid()}")


def role(kind: str, endpoint: str, key: str) -> None:
    """The reader (`ring`) or the slow consumer (`slow`), until SIGTERM."""
    cfg = build_zenoh_config(ZenohConfig(connect=(endpoint,)))
    got = [0]
    with zenoh.open(cfg) as session:
        if kind == "slow":
            sub = session.declare_subscriber(
                key, zenoh.handlers.Callback(lambda s: time.sleep(1.0), indirect=False))
        else:
            sub = session.declare_subscriber(key, zenoh.handlers.RingChannel(100_000))
        stop = [False]
        signal.signal(signal.SIGTERM, lambda *_: stop.__setitem__(0, True))
        while not stop[0]:
            if kind == "ring":
                while sub.try_recv() is not None:
                    got[0] += 1
            time.sleep(0.01)
        print(got[0], flush=True)
        os._exit(0)  # a sleeping callback would hold close() for its second


def measure(bus: ZenohBus, key: str, congestion: Congestion, hz: float,
            seconds: float, payload: bytes) -> tuple[list[float], int]:
    pub = bus.declare_publisher(key, congestion)
    period, times, overruns = 1.0 / hz, [], 0
    t_next = time.monotonic()
    for _ in range(int(seconds * hz)):
        t = time.monotonic()
        pub.put(payload)
        dt = time.monotonic() - t
        times.append(dt)
        overruns += dt > period
        t_next += period
        time.sleep(max(0.0, t_next - time.monotonic()))
    pub.close()
    return times, overruns


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--hz", type=float, default=50.0)
    p.add_argument("--bytes", type=int, default=300, help="a sample (a FollowerState: ~300)")
    p.add_argument("--drop-wait-us", type=int, default=None)
    args = p.parse_args()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        endpoint = loopback_endpoint(s.getsockname()[1])
    user = None
    if args.drop_wait_us is not None:  # the publisher's own config: it is the one that waits
        user = f"/tmp/bench_slow_consumer_{os.getpid()}.json5"
        Path(user).write_text(json.dumps({"transport": {"link": {"tx": {"queue": {
            "congestion_control": {"drop": {"wait_before_drop": args.drop_wait_us}}}}}}}))
    with ZenohBus(ZenohConfig(listen=(endpoint,), user_config_path=user)) as bus:
        for slow in (False, True):
            for congestion in (Congestion.BLOCK, Congestion.DROP):
                key = KEYS.follower_state(1 if congestion is Congestion.BLOCK else 2)
                kids = [subprocess.Popen([sys.executable, __file__, "--role", kind,
                                          endpoint, key], stdout=subprocess.PIPE, text=True)
                        for kind in (("ring", "slow") if slow else ("ring",))]
                pub = bus.declare_publisher(key, Congestion.DROP)
                deadline = time.monotonic() + 10.0
                while not pub.matched() and time.monotonic() < deadline:
                    time.sleep(0.01)
                time.sleep(1.0)  # the slow consumer's link up and its subscriber declared
                pub.close()
                times, overruns = measure(bus, key, congestion, args.hz, args.seconds,
                                          bytes(args.bytes))
                for kid in kids:
                    kid.send_signal(signal.SIGTERM)
                got = [kid.communicate(timeout=30)[0].strip() for kid in kids]
                ms = sorted(1000.0 * t for t in times)
                print(f"{'slow consumer' if slow else 'no slow consumer':16} "
                      f"{congestion.name:5}: put p50 {statistics.median(ms):.3f} ms, "
                      f"p99 {ms[int(0.99 * len(ms))]:.3f} ms, max {ms[-1]:.1f} ms, "
                      f"over a period {100.0 * overruns / len(ms):.1f} %, "
                      f"reader got {got[0]} of {len(ms)}", flush=True)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--role":
        role(sys.argv[2], sys.argv[3], sys.argv[4])
    else:
        main()
