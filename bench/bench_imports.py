"""What each import costs a follower (issue 15: lean processes): RSS and time, in order.

In a fresh interpreter per repeat, imports the follower's dependencies one after another
(as `agents.follower` pulls them in) and prints the VmRSS each adds and the wall time it
took; then, for reference, what a follower no longer imports (each in a fresh interpreter
on top of agents.follower).  Times depend on machine load; RSS does not (much).

Run: python bench/bench_imports.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys

CHAIN = ("msgpack", "zenoh", "pymavlink.dialects.v20.common", "transport.zenoh_bus",
         "agents.mavlink.adapter", "agents.follower_fast", "agents.follower")
NOT_IMPORTED = ("numpy", "cryptography.x509", "matplotlib.pyplot", "mcap.writer", "numba")

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
    print("| import (in order) | adds RSS [MB] | RSS after [MB] | time [ms], median |")
    print("|---|---|---|---|")
    for k, (name, rss, _) in enumerate(runs[0]):
        added = rss - runs[0][k - 1][1] if k else rss
        ms = statistics.median(r[k][2] for r in runs) * 1e3
        print(f"| {name} | {added:.1f} | {rss:.1f} | {ms:.0f} |")
    print("\nNot imported by a follower any more (each on top of agents.follower):")
    for name in NOT_IMPORTED:
        try:
            rows = probe(("agents.follower", name))
        except subprocess.CalledProcessError:
            print(f"| {name} | not installed |")
            continue
        print(f"| {name} | +{rows[-1][1] - rows[-2][1]:.1f} MB | {rows[-1][2] * 1e3:.0f} ms |")


if __name__ == "__main__":
    main()
