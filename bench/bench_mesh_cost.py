"""What a Zenoh topology costs before any data flows: K processes, CPU each.

    python bench/bench_mesh_cost.py --processes 64 [--insecure] [--star] [--status-hz 1] \
        [--clock per-process|per-host]

Every process opens a Zenoh session as enclose's followers do (peer, multicast scouting
off, 127.0.0.1, the one-thread runtime, mTLS and the swarm's ACL unless --insecure),
declares a liveliness token, subscribes to every follower's status and, with
--status-hz > 0, publishes a 2-KB status (a follower's counters) at that rate: enclose's
membership heartbeat, O(K^2) messages over the mesh.  Peers find each other through the
first one and gossip into a full mesh (K (K - 1) / 2 links); `--star` makes process 0 a
router and the rest its clients (one link each).  `--clock per-host` runs enclose's
clock exchange over hosts (transport.clock_sync: the router probes, every client
listens; needs --star), `--clock per-process` the same probes between every pair of
processes, as enclose once did (needs --insecure: the ACL now gives clock keys
to routers only).  After a settling time the script reads
each process's CPU from /proc over a window and prints the mean and the worst, and the
machine's busy share.  Nothing else should run meanwhile.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from deploy.report.cpu_load import busy_pct, machine_ticks, process_cpu_s
from transport.bus import Congestion
from transport.credentials import Identity, identity_file, make_credentials
from transport.key_exprs import SwarmKeys
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

KEYS = SwarmKeys("meshcost")
STATUS_BYTES = 2048


def child(index: int, args: argparse.Namespace, cred: str | None, life_s: float) -> None:
    hub = args.star and index == 0
    name = "router-0" if hub else f"follower-{index}"
    ident = None if cred is None else Identity.load(identity_file(Path(cred), name))
    mode = ("router" if hub else "client") if args.star else "peer"
    endpoint = f"{'tcp' if cred is None else 'tls'}/127.0.0.1:{args.port}"
    cfg = ZenohConfig(mode=mode, listen=(endpoint,) if index == 0 else (),
                      connect=() if index == 0 else (endpoint,), identity=ident,
                      runtime="one_thread", user_config_path=args.zenoh_config)
    with ZenohBus(cfg) as bus:
        deadline = time.monotonic() + life_s
        if args.clock == "per-process":  # every process probes, as a router of its own
            bus.start_clock_sync(KEYS, f"router-{index}", args.processes, probe=True)
        elif args.clock == "per-host":
            bus.start_clock_sync(KEYS, "router-0", 1, probe=hub)
        if hub:
            while time.monotonic() < deadline:
                time.sleep(0.5)
            return
        bus.declare_token(KEYS.alive("follower", index))
        sub = bus.subscribe(KEYS.status_of("follower"), 256)
        pub = bus.declare_publisher(KEYS.status("follower", index), Congestion.DROP)
        period_s = 1.0 / args.status_hz if args.status_hz > 0 else 1.0
        while time.monotonic() < deadline:
            if args.status_hz > 0:
                pub.put(b"s" * STATUS_BYTES)
            sub.drain()
            time.sleep(period_s)


def measure(args: argparse.Namespace) -> dict[str, float]:
    cred = None
    if not args.insecure:
        cred = tempfile.mkdtemp(prefix="meshcost-")
        make_credentials(Path(cred), KEYS, args.processes, 0, n_routers=1 if args.star else 0)
    life_s = args.settle_s + args.window_s + 5.0
    argv = [sys.executable, __file__, *sys.argv[1:]]
    procs = [subprocess.Popen([*argv, f"--child={i},{cred or ''},{life_s}"])
             for i in range(args.processes)]
    try:
        time.sleep(args.settle_s)
        before = [process_cpu_s(p.pid) or 0.0 for p in procs]
        machine0 = machine_ticks()
        t0 = time.monotonic()
        time.sleep(args.window_s)
        after = [process_cpu_s(p.pid) or 0.0 for p in procs]
        machine1 = machine_ticks()
        window = time.monotonic() - t0
    finally:
        for p in procs:
            p.wait(timeout=life_s + 30.0)
    share = [100.0 * (b - a) / window for a, b in zip(before, after, strict=True)]
    busy = None if machine0 is None or machine1 is None else busy_pct(machine0, machine1)
    clients = share[1:] if args.star else share
    return {"mean_pct": sum(clients) / len(clients), "max_pct": max(clients),
            "hub_pct": share[0] if args.star else 0.0,
            "machine_pct": float("nan") if busy is None else busy}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--processes", type=int, default=64)
    p.add_argument("--insecure", action="store_true", help="plain TCP, no mTLS or ACL")
    p.add_argument("--star", action="store_true", help="process 0 a router, the rest clients")
    p.add_argument("--status-hz", type=float, default=1.0, help="0: no status, only tokens")
    p.add_argument("--settle-s", type=float, default=30.0)
    p.add_argument("--window-s", type=float, default=20.0)
    p.add_argument("--port", type=int, default=47311)
    p.add_argument("--zenoh-config", default=None, metavar="JSON5",
                   help="a Zenoh config for every process (e.g. a longer lease)")
    p.add_argument("--clock", choices=("none", "per-process", "per-host"), default="none",
                   help="clock probes: none, between every pair, or the routers' (--star)")
    args, rest = p.parse_known_args()
    if args.clock == "per-host" and not args.star:
        p.error("--clock per-host needs --star (a router to probe)")
    if args.clock == "per-process" and not args.insecure:
        p.error("--clock per-process needs --insecure (clock keys are the routers' now)")
    if rest and rest[-1].startswith("--child="):
        index, cred, life_s = rest[-1].split("=", 1)[1].split(",")
        child(int(index), args, cred or None, float(life_s))
        return 0
    r = measure(args)
    what = "star (router + clients)" if args.star else "full mesh of peers"
    print(json.dumps({"processes": args.processes, "topology": what,
                      "security": not args.insecure, "status_hz": args.status_hz,
                      "clock": args.clock,
                      **{k: round(v, 2) for k, v in r.items()}}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
