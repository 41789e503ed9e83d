"""What a Zenoh put costs the thread that calls it, by transport and subscriber count.

    python bench/bench_put_cost.py [--subscribers 0 1 4] [--puts 500] [--rounds 4]

One session holds follower-0's certificate (with `tls`) and publishes a 330-byte payload on
follower-0's state key at 100 Hz; K subscriber processes (follower-1..K) connect to it and
drain.  Printed: the calling thread's CPU per put (`time.thread_time` around each put),
per round.  Modes: `tcp` (`--insecure`), `tls` (mTLS and the swarm's access control, as
enclose runs), `tls-no-acl` (mTLS, access control off): where security's cost is, or is not.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import zenoh

from deploy.launch.ports import free_tcp_port
from transport.credentials import Identity, identity_file, make_credentials
from transport.key_exprs import SwarmKeys
from transport.zenoh_config import ZenohConfig, build_zenoh_config

KEYS = SwarmKeys("putcost")
MODES = ("tcp", "tls", "tls-no-acl")


def config(mode: str, creds: str, name: str, listen: tuple[str, ...] = (),
           connect: tuple[str, ...] = ()) -> zenoh.Config:
    ident = None if mode == "tcp" else Identity.load(identity_file(Path(creds), name))
    cfg = build_zenoh_config(ZenohConfig(listen=listen, connect=connect, identity=ident,
                                         runtime="one_thread"))
    if mode == "tls-no-acl":
        cfg.insert_json5("access_control", '{"enabled": false}')
    return cfg


def subscriber(mode: str, creds: str, name: str, endpoint: str) -> int:
    with zenoh.open(config(mode, creds, name, connect=(endpoint,))) as session:
        sub = session.declare_subscriber(KEYS.follower_state(0),
                                         zenoh.handlers.RingChannel(1000))
        index = int(name.rpartition("-")[2])
        session.liveliness().declare_token(KEYS.alive("follower", index))
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            while sub.try_recv() is not None:
                pass
            time.sleep(0.05)
    return 0


def wait_linked(session: zenoh.Session, k: int, timeout_s: float = 30.0) -> int:
    watch = session.liveliness().declare_subscriber(
        KEYS.all_alive(), zenoh.handlers.RingChannel(100), history=True)
    seen: set[str] = set()
    deadline = time.monotonic() + timeout_s
    while len(seen) < k and time.monotonic() < deadline:
        sample = watch.try_recv()
        if sample is None:
            time.sleep(0.01)
        else:
            seen.add(str(sample.key_expr))
    return len(seen)


def measure(mode: str, k: int, creds: str, puts: int, rounds: int) -> None:
    endpoint = f"{'tcp' if mode == 'tcp' else 'tls'}/127.0.0.1:{free_tcp_port()}"
    procs = [subprocess.Popen([sys.executable, __file__, "--subscriber", mode, creds,
                               f"follower-{i + 1}", endpoint]) for i in range(k)]
    try:
        with zenoh.open(config(mode, creds, "follower-0", listen=(endpoint,))) as session:
            pub = session.declare_publisher(KEYS.follower_state(0))
            linked = wait_linked(session, k)
            time.sleep(2.0)  # the subscribers' declarations reach us
            payload, per_round = os.urandom(330), []
            for _ in range(rounds):
                used = 0.0
                for _ in range(puts):
                    t0 = time.thread_time()
                    pub.put(payload)
                    used += time.thread_time() - t0
                    time.sleep(0.01)
                per_round.append(used / puts * 1e6)
        print(f"{mode:10s} subscribers {k} (linked {linked}): put costs the caller "
              f"{', '.join(f'{us:.1f}' for us in per_round)} us", flush=True)
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            p.wait(10)


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "--subscriber":
        return subscriber(*sys.argv[2:6])
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--subscribers", type=int, nargs="+", default=[0, 1, 4])
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    parser.add_argument("--puts", type=int, default=500)
    parser.add_argument("--rounds", type=int, default=4)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory() as tmp:
        creds = str(make_credentials(Path(tmp) / "c", KEYS, max(args.subscribers) + 1, 0))
        for mode in args.modes:
            for k in args.subscribers:
                measure(mode, k, creds, args.puts, args.rounds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
