"""A stolen host folder against the other host, and a witness there (test_insider.py).

    python -m tests.integration.host_insider attack --folder creds/companion \
        --own tls/10.77.0.2:7447 --hub tls/10.77.0.1:7447 --swarm S --seconds T --out a.json
    python -m tests.integration.host_insider witness --identity creds/ground/router-0.json \
        --hub tls/10.77.0.1:7447 --swarm S --stop FILE --out w.json

`attack` holds exactly one host's folder, its router's key included, and uses every
identity in it, four ways: a client of its own host's router as that router (whose
clients it may feed), a client of the hub's router as the router, a router of its own
linked to the hub's as the router, and a client of the hub's as each of its processes.
Each puts a marked payload (MARK) on keys of the other host's processes (the control,
the truth, every follower's sensing, the simulator's, recorder's and targets' statuses,
the hub router's clock probes) and on one of its own processes' keys (a follower's
status: the positive control, which must arrive), and declares liveliness tokens for
processes of the other host that do not exist (no real token to mistake them for).
`witness` subscribes to every key of the swarm and to every token on the other host,
and counts what arrives marked, by key, until its stop file appears.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

from transport.credentials import Identity
from transport.key_exprs import SwarmKeys
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

MARK = b"HOSTILE-HOST-FOLDER"
PERIOD_S = 0.5
N_FOLLOWERS = 4
OWN_FOLLOWER = 0  # of the stolen host: its status is the positive control


def forged_keys(keys: SwarmKeys) -> list[str]:
    """Keys of the other host's processes, and the control, truth and sensing."""
    return [keys.control(), keys.truth(),
            *(keys.sensor_targets(i) for i in range(N_FOLLOWERS)),
            keys.status("sim", 0), keys.status("recorder", 0), keys.status("launcher", 0),
            keys.status("target", 0), keys.status("target", 1), keys.clock("router", 0)]


def forged_tokens(keys: SwarmKeys) -> list[str]:
    return [keys.alive("target", 7), keys.alive("sim", 1), keys.alive("launcher", 0)]


def own_key(keys: SwarmKeys) -> str:
    return keys.status("follower", OWN_FOLLOWER)


def _session(mode: str, endpoint: str, identity: Path) -> ZenohBus:
    return ZenohBus(ZenohConfig(mode=mode, connect=(endpoint,),
                                identity=Identity.load(identity)))


def attack(args: argparse.Namespace) -> int:
    folder, keys = Path(args.folder), SwarmKeys(args.swarm)
    router = next(folder.glob("router-*.json"))
    processes = sorted(p for p in folder.glob("*.json")
                       if p.stem.startswith(("follower-", "target-")))
    sessions = {"own-router-as-router": _session("client", args.own, router),
                "hub-as-router": _session("client", args.hub, router),
                "hub-as-rogue-router": _session("router", args.hub, router),
                **{f"hub-as-{p.stem}": _session("client", args.hub, p) for p in processes}}
    tokens = [bus.declare_token(key) for bus in sessions.values()
              for key in forged_tokens(keys)]
    sent: Counter[str] = Counter()
    end = time.monotonic() + args.seconds
    seq = 0
    while time.monotonic() < end:
        for name, bus in sessions.items():
            for key in [*forged_keys(keys), own_key(keys)]:
                bus.publish(key, MARK + f"-{name}-{seq}".encode())
                sent[key] += 1
        seq += 1
        time.sleep(PERIOD_S)
    for token in tokens:
        token.close()
    for bus in sessions.values():
        bus.close()
    Path(args.out).write_text(json.dumps({"sessions": sorted(sessions), "sent": sent,
                                          "tokens": len(tokens)}, indent=1))
    return 0


def witness(args: argparse.Namespace) -> int:
    keys = SwarmKeys(args.swarm)
    got: Counter[str] = Counter()
    tokens: set[str] = set()
    with _session("client", args.hub, Path(args.identity)) as bus:
        sub = bus.subscribe(keys.everything(), capacity=65536)
        alive = bus.watch_alive(keys.all_alive())
        print("ready", flush=True)
        while not Path(args.stop).exists():
            for r in sub.drain():
                if r.payload.startswith(MARK):
                    got[r.key] += 1
            tokens |= set(alive.poll()) & set(forged_tokens(keys))
            time.sleep(0.05)
    Path(args.out).write_text(json.dumps({"marked": got, "tokens": sorted(tokens)}, indent=1))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.integration.host_insider")
    sub = parser.add_subparsers(required=True)
    a = sub.add_parser("attack")
    a.add_argument("--folder", required=True)
    a.add_argument("--own", required=True, help="its own host's router endpoint")
    a.add_argument("--seconds", type=float, required=True)
    a.set_defaults(func=attack)
    w = sub.add_parser("witness")
    w.add_argument("--identity", required=True)
    w.add_argument("--stop", required=True, help="ends when this file exists")
    w.set_defaults(func=witness)
    for p in (a, w):
        p.add_argument("--hub", required=True, help="the other host's router endpoint")
        p.add_argument("--swarm", required=True)
        p.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
