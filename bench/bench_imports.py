"""What each import costs a follower (issue 15: lean processes): RSS and time, in order.

In a fresh interpreter per repeat, imports the follower's dependencies one after another
(as `agents.follower.main` pulls them in) and prints the VmRSS each adds and the wall time it
took; then, for reference, what a follower no longer imports (each in a fresh interpreter
on top of agents.follower.main); then what each MAVLink dialect adds on top of what a follower
holds before it (the agents' lean one, pymavlink's common and minimal).  Times depend on
machine load; RSS does not (much), but it does on whether the modules' bytecode is cached:
with PYTHONDONTWRITEBYTECODE set and no __pycache__, every interpreter compiles the
project's modules (lean_common.py among them) from source.

Run: python bench/bench_imports.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

CHAIN = ("msgpack", "zenoh", "agents.mavlink.lean_common", "transport.zenoh_bus",
         "agents.mavlink.adapter", "agents.law.paper", "agents.follower.main")
NOT_IMPORTED = ("numpy", "pymavlink.dialects.v20.common", "cryptography.x509",
                "matplotlib.pyplot", "mcap.writer", "numba")
DIALECT_BASE = ("msgpack", "zenoh", "hashlib", "json", "logging", "struct", "fastcrc")
DIALECTS = ("agents.mavlink.lean_common", "pymavlink.dialects.v20.common",
            "pymavlink.dialects.v20.minimal")

PROBE = """
import importlib, json, sys, time
def rss_mb():
    with open('/proc/self/status') as f:
        return next(int(l.split()[1]) for l in f if l.startswith('VmRSS')) / 1024
out = [("python", rss_mb(), 0.0)]
for name in sys.argv[1:]:
    t = time.perf_counter()
    importlib.import_module(name)
    out.append((name, rss_mb(), time.perf_counter() - t))
print(json.dumps(out))
"""


def probe(modules: tuple[str, ...]) -> list[tuple[str, float, float]]:
    out = subprocess.run([sys.executable, "-c", PROBE, *modules], capture_output=True,
                         text=True, check=True, timeout=120).stdout
    return [(str(a), float(b), float(c)) for a, b, c in json.loads(out)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    runs = [probe(CHAIN) for _ in range(args.repeats)]
    print(f"PYTHONDONTWRITEBYTECODE={os.environ.get('PYTHONDONTWRITEBYTECODE', '')!r} "
          f"PYTHONPYCACHEPREFIX={os.environ.get('PYTHONPYCACHEPREFIX', '')!r}\n")
    print("| import (in order) | adds RSS [MB] | RSS after [MB] | time [ms], median |")
    print("|---|---|---|---|")
    for k, (name, rss, _) in enumerate(runs[0]):
        added = rss - runs[0][k - 1][1] if k else rss
        ms = statistics.median(r[k][2] for r in runs) * 1e3
        print(f"| {name} | {added:.1f} | {rss:.1f} | {ms:.0f} |")
    print("\nNot imported by a follower any more (each on top of agents.follower.main):")
    for name in NOT_IMPORTED:
        try:
            rows = probe(("agents.follower.main", name))
        except subprocess.CalledProcessError:
            print(f"| {name} | not installed |")
            continue
        print(f"| {name} | +{rows[-1][1] - rows[-2][1]:.1f} MB | {rows[-1][2] * 1e3:.0f} ms |")
    print(f"\nMAVLink dialects, each on top of {', '.join(DIALECT_BASE)}:")
    print("| dialect | adds RSS [MB], median | time [ms], median |")
    print("|---|---|---|")
    for name in DIALECTS:
        rows = [probe((*DIALECT_BASE, name)) for _ in range(args.repeats)]
        added = statistics.median(r[-1][1] - r[-2][1] for r in rows)
        ms = statistics.median(r[-1][2] for r in rows) * 1e3
        print(f"| {name} | {added:.2f} | {ms:.1f} |")


if __name__ == "__main__":
    main()
