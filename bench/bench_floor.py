"""What the design's own traffic costs a follower per tick, with no work of ours in it.

    python bench/bench_floor.py [--followers 4] [--rate-hz 50] [--runs 3] [--insecure] \
        [--zenoh-runtime split|one_thread]

Real processes on loopback, each as its enclose counterpart talks, and nothing else:
- `follower-i` (i < --followers, a ring): a Zenoh peer session as a follower opens it
  (transport.zenoh_bus, mTLS and the swarm's ACL unless --insecure), on its own tick
  phase.  Each tick it drains its two neighbours' states and its sensor's observations
  (msgpack-decoding each), reads its vehicle's datagrams, sends one setpoint-sized datagram
  and publishes a state of a FollowerState's size.  No law, no checks, no journal, no
  clock map, no MAVLink framing or signing: the floor under a follower's tick.
- `sim`: one UDP socket per vehicle, answering each setpoint with a LOCAL_POSITION_NED-sized
  datagram each tick, and the targets each follower observes on its sensor key.
- `recorder`: subscribes to every follower's state (the third subscriber of each state),
  drained every 20 ms and not decoded: the floor under the recorder's CPU per message.

After --settle-s the parent reads each process's CPU over all its threads
(/proc/<pid>/task/*/stat) over --window-s and prints a follower's CPU per tick (the median
follower, its main thread and Zenoh's threads apart), the recorder's CPU per state it
takes in, the machine's busy share and the spread over runs.  Compare with
`python bench/bench_tick_cost.py --case paper`, a real follower on the same traffic.
Nothing else should run meanwhile.
"""

from __future__ import annotations

import argparse
import json
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import msgpack

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from deploy.report.cpu_load import busy_pct, machine_ticks, process_cpu_s
from transport.bus import Congestion
from transport.credentials import Identity, identity_file, make_credentials
from transport.key_exprs import SwarmKeys
from transport.network_schema import ZENOH_RUNTIMES
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

KEYS = SwarmKeys("floor")
# MAVLink 2 frames as a follower and its vehicle send them: a 10-byte header, the payload,
# a 2-byte CRC and a 13-byte signature.
SETPOINT_BYTES = 10 + 53 + 2 + 13  # SET_POSITION_TARGET_LOCAL_NED (78 B, as strace shows)
POSITION_BYTES = 10 + 28 + 2 + 13  # LOCAL_POSITION_NED
STATE_FLOATS = 24  # a FollowerState's wire array is ~250 B


def session(name: str, args: argparse.Namespace, cred: str | None) -> ZenohBus:
    ident = None if cred is None else Identity.load(identity_file(Path(cred), name))
    proto = "tcp" if cred is None else "tls"
    endpoint = f"{proto}/127.0.0.1:{args.port}"
    hub = name == "sim"
    cfg = ZenohConfig(listen=(endpoint,) if hub else (), connect=() if hub else (endpoint,),
                      identity=ident, runtime=args.zenoh_runtime, lowlatency=args.lowlatency)
    return ZenohBus(cfg)


def follower(i: int, args: argparse.Namespace, cred: str | None, end_s: float) -> None:
    n, period_s = args.followers, 1.0 / args.rate_hz
    with session(f"follower-{i}", args, cred) as bus:
        subs = [bus.subscribe(KEYS.follower_state(j), 8) for j in ((i - 1) % n, (i + 1) % n)]
        subs.append(bus.subscribe(KEYS.sensor_targets(i), 8))
        pub = bus.declare_publisher(KEYS.follower_state(i), Congestion.DROP)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        sock.setblocking(False)
        vehicle = ("127.0.0.1", args.port + 1 + i)
        setpoint = bytes(SETPOINT_BYTES)
        state = [float(k) for k in range(STATE_FLOATS)]
        unpack, pack = msgpack.unpackb, msgpack.packb
        next_s = (time.time() // period_s + 1 + i / n) * period_s
        counts = {"ticks": 0, "states": 0, "datagrams": 0}
        while next_s < end_s:
            time.sleep(max(0.0, next_s - time.time()))
            for sub in subs:
                for received in sub.drain():
                    unpack(received.payload)
                    counts["states"] += 1
            while True:
                try:
                    sock.recv(2048)
                    counts["datagrams"] += 1
                except BlockingIOError:
                    break
            sock.sendto(setpoint, vehicle)
            state[0] = time.time()
            pub.put(pack([f"follower-{i}", i, state]))
            counts["ticks"] += 1
            next_s += period_s
        if args.counts:  # what a tick received: the bench's own check that traffic flowed
            Path(args.counts, f"follower-{i}.json").write_text(json.dumps(counts))


def sim(args: argparse.Namespace, cred: str | None, end_s: float) -> None:
    n, period_s = args.followers, 1.0 / args.rate_hz
    with session("sim", args, cred) as bus:
        pubs = [bus.declare_publisher(KEYS.sensor_targets(i), Congestion.DROP) for i in range(n)]
        socks = []
        for i in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.bind(("127.0.0.1", args.port + 1 + i))
            s.setblocking(False)
            socks.append(s)
        peers: list[tuple[str, int] | None] = [None] * n
        position = bytes(POSITION_BYTES)
        next_s = (time.time() // period_s + 1) * period_s
        while next_s < end_s:
            time.sleep(max(0.0, next_s - time.time()))
            for i, s in enumerate(socks):
                while True:
                    try:
                        _, peers[i] = s.recvfrom(2048)
                    except BlockingIOError:
                        break
                addr = peers[i]
                if addr is not None:
                    s.sendto(position, addr)
                pubs[i].put(msgpack.packb(["sim-0", i, [[1.0, 2.0, time.time()]] * 2]))
            next_s += period_s


def recorder(args: argparse.Namespace, cred: str | None, end_s: float) -> None:
    with session("recorder", args, cred) as bus:
        sub = bus.subscribe(KEYS.all_follower_states(), 1024)
        messages = 0
        while time.time() < end_s:
            messages += len(sub.drain())
            time.sleep(0.02)
        if args.counts:
            Path(args.counts, "recorder.json").write_text(json.dumps({"messages": messages}))


def thread_cpu_s(pid: int) -> dict[str, float]:
    """CPU seconds of `pid`'s main thread and of its other threads (Zenoh's)."""
    main = process_cpu_s(pid, Path(f"/proc/{pid}/task")) or 0.0  # first: whole >= main
    return {"main": main, "zenoh": (process_cpu_s(pid) or 0.0) - main}


def child_argv(args: argparse.Namespace, port: int, counts_dir: str) -> list[str]:
    """This script's command line for a child of the run `args` describes."""
    argv = [sys.executable, __file__, f"--followers={args.followers}",
            f"--rate-hz={args.rate_hz}", f"--zenoh-runtime={args.zenoh_runtime}",
            f"--port={port}", f"--counts={counts_dir}"]
    return argv + ["--insecure"] * args.insecure + ["--lowlatency"] * args.lowlatency


def one_run(args: argparse.Namespace, port: int) -> dict[str, float]:
    """One floor run: its processes started, measured over the window and stopped."""
    with tempfile.TemporaryDirectory(prefix="floor-") as tmp:
        cred = None
        if not args.insecure:
            cred = str(Path(tmp, "credentials"))
            make_credentials(Path(cred), KEYS, args.followers, 0)
        counts_dir = Path(tmp, "counts")
        counts_dir.mkdir()
        return _measured(args, child_argv(args, port, str(counts_dir)), cred, counts_dir)


def _measured(args: argparse.Namespace, base: list[str], cred: str | None,
              counts_dir: Path) -> dict[str, float]:
    end_s = time.time() + args.settle_s + args.window_s + 2.0
    roles = ["sim", "recorder"] + [f"follower-{i}" for i in range(args.followers)]
    procs = {r: subprocess.Popen([*base, f"--child={r},{cred or ''},{end_s}"]) for r in roles}
    try:
        time.sleep(args.settle_s)
        pids = {r: p.pid for r, p in procs.items()}
        before = {r: thread_cpu_s(pid) for r, pid in pids.items()}
        machine0 = machine_ticks()
        t0 = time.monotonic()
        time.sleep(args.window_s)
        after = {r: thread_cpu_s(pid) for r, pid in pids.items()}
        machine1 = machine_ticks()
        window_s = time.monotonic() - t0
    finally:
        for p in procs.values():
            try:
                p.wait(timeout=max(0.0, end_s - time.time()) + 30.0)
            except subprocess.TimeoutExpired:  # a child that hangs is stopped, not left
                p.kill()
                p.wait()
    ticks = window_s * args.rate_hz
    counts = [json.loads(f.read_text()) for f in counts_dir.glob("follower-*.json")]
    recorded = json.loads((counts_dir / "recorder.json").read_text())["messages"]
    if len(counts) != args.followers or min(c["ticks"] for c in counts) == 0:
        raise SystemExit(f"bench_floor: {len(counts)} of {args.followers} followers reported")
    us = {r: {g: (after[r][g] - before[r][g]) / ticks * 1e6 for g in after[r]} for r in after}
    followers = sorted((us[r] for r in roles[2:]), key=lambda g: g["main"] + g["zenoh"])
    mid = followers[len(followers) // 2]
    busy = None if machine0 is None or machine1 is None else busy_pct(machine0, machine1)
    return {"follower_us": mid["main"] + mid["zenoh"], "main_us": mid["main"],
            "zenoh_us": mid["zenoh"], "sim_us": sum(us["sim"].values()),
            # each follower publishes a state a tick; the recorder takes them all in
            "recorder_us_per_msg": sum(us["recorder"].values()) / args.followers,
            "recorded_share": recorded / sum(c["ticks"] for c in counts),
            "busy_pct": float("nan") if busy is None else busy,
            "states_per_tick": min(c["states"] / c["ticks"] for c in counts),
            "datagrams_per_tick": min(c["datagrams"] / c["ticks"] for c in counts)}


def floor_args(followers: int, rate_hz: float, insecure: bool, runtime: str) -> argparse.Namespace:
    """A floor run's settings, for a caller of `one_run` (bench_tick_cost.py --floor)."""
    # A larger mesh takes longer to link on 2 cores (64 followers: ~20 s).
    settle_s = max(8.0, 0.4 * followers)
    return parser().parse_args([f"--followers={followers}", f"--rate-hz={rate_hz}",
                                f"--zenoh-runtime={runtime}", f"--settle-s={settle_s}"]
                               + ["--insecure"] * insecure)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--followers", type=int, default=4)
    p.add_argument("--rate-hz", type=float, default=50.0)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--insecure", action="store_true", help="plain TCP, no mTLS or ACL")
    p.add_argument("--zenoh-runtime", choices=ZENOH_RUNTIMES, default="split")
    p.add_argument("--lowlatency", action="store_true",
                   help="Zenoh's low-latency transport (transport/unicast/lowlatency)")
    p.add_argument("--settle-s", type=float, default=8.0)
    p.add_argument("--window-s", type=float, default=20.0)
    p.add_argument("--port", type=int, default=47411)
    p.add_argument("--counts", default="", help=argparse.SUPPRESS)
    return p


def main() -> int:
    args, rest = parser().parse_known_args()
    if rest and rest[-1].startswith("--child="):
        role, cred, end_s = rest[-1].split("=", 1)[1].split(",")
        if role == "sim":
            sim(args, cred or None, float(end_s))
        elif role == "recorder":
            recorder(args, cred or None, float(end_s))
        else:
            follower(int(role.rpartition("-")[2]), args, cred or None, float(end_s))
        return 0
    rows = []
    for k in range(args.runs):
        r = one_run(args, args.port + 100 * k)
        rows.append(r)
        print(f"run {k + 1}/{args.runs}: follower {r['follower_us']:.0f} us/tick (main "
              f"{r['main_us']:.0f}, Zenoh's threads {r['zenoh_us']:.0f}), machine "
              f"{r['busy_pct']:.0f} % busy; each follower received >= "
              f"{r['states_per_tick']:.2f} states and {r['datagrams_per_tick']:.2f} datagrams "
              f"a tick; recorder {r['recorder_us_per_msg']:.1f} us a message "
              f"({100 * r['recorded_share']:.1f} % of the states sent)", flush=True)
    summary = {name: {"median": statistics.median(r[name] for r in rows),
                      "min": min(r[name] for r in rows), "max": max(r[name] for r in rows)}
               for name in rows[0]}
    print(json.dumps({"followers": args.followers, "rate_hz": args.rate_hz,
                      "secure": not args.insecure, "zenoh_runtime": args.zenoh_runtime,
                      "runs": args.runs, **summary}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
