"""An insider within its rights, at the door (issue 51, items 3 and 4), run as its own OS
process with follower j's identity (its certificate, the CA, the ACL):

    python -m tests.integration.door_insider --mode slow|big --identity FILE \
        --endpoint E --swarm S --progress P --seconds T --out report.json

- `slow`: a subscriber on the whole swarm's key space whose callback sleeps 1 s per
  sample, on Zenoh's receiving thread (`indirect=False`), so that this process stops
  reading its links: the publishers' queues towards it fill.  A follower's rights let it
  subscribe to everything (transport.access).
- `big`: `--puts` puts of `--size` bytes (20 MB) on follower j's own state key, which its
  rights cover, one a second, with BLOCK so that every byte leaves.

It starts once the run is flying (progress.json "running") and writes what it did.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

import zenoh

from tests.integration.rogue import wait_running
from transport.bus import Congestion
from transport.credentials import Identity
from transport.key_exprs import SwarmKeys
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

SLEEP_S = 1.0  # per sample, in the slow subscriber's callback


def slow(bus: ZenohBus, keys: SwarmKeys, seconds: float, report: dict[str, float]) -> None:
    stop = threading.Event()

    def stall(sample: zenoh.Sample) -> None:
        report["slow_samples"] += 1
        if not stop.is_set():
            stop.wait(SLEEP_S)

    sub = bus.session.declare_subscriber(keys.everything(),
                                         zenoh.handlers.Callback(stall, indirect=False))
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        time.sleep(0.1)
    stop.set()  # the callback returns at once from here on: the session can close
    sub.undeclare()


def big(bus: ZenohBus, keys: SwarmKeys, j: int, args: argparse.Namespace,
        report: dict[str, float]) -> None:
    pub = bus.declare_publisher(keys.follower_state(j), Congestion.BLOCK)
    deadline = time.monotonic() + 20.0
    while not pub.matched() and time.monotonic() < deadline:
        time.sleep(0.05)
    payload = bytes(args.size)
    for _ in range(args.puts):
        t = time.monotonic()
        pub.put(payload)
        report["big_sent"] += 1
        report["big_put_s_max"] = max(report["big_put_s_max"], time.monotonic() - t)
        time.sleep(max(0.0, 1.0 - (time.monotonic() - t)))


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--mode", choices=("slow", "big"), required=True)
    p.add_argument("--identity", required=True, help="a follower's identity file")
    p.add_argument("--endpoint", required=True)
    p.add_argument("--swarm", required=True)
    p.add_argument("--progress", required=True, help="the run's progress.json")
    p.add_argument("--seconds", type=float, default=30.0, help="slow: how long")
    p.add_argument("--puts", type=int, default=5, help="big: how many")
    p.add_argument("--size", type=int, default=20_000_000, help="big: bytes a put")
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    keys, ident = SwarmKeys(args.swarm), Identity.load(args.identity)
    j = int(ident.name.rsplit("-", 1)[1])
    report = dict.fromkeys(("slow_samples", "big_sent", "big_put_s_max"), 0.0)
    wait_running(Path(args.progress))
    with ZenohBus(ZenohConfig(connect=(args.endpoint,), identity=ident)) as bus:
        if args.mode == "slow":
            slow(bus, keys, args.seconds, report)
        else:
            big(bus, keys, j, args, report)
        report["linked"] = float(bool(bus.peers()))
    Path(args.out).write_text(json.dumps(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
