"""One-way neighbour-state latency in the running swarm (issue 15: latency you can quote).

Runs `enclose run SCENARIO --latency-stamps` (mTLS + access control on, as by default):
every follower stamps each sample as it reaches its process (transport.zenoh_bus) and
tallies arrival minus the sender's Zenoh HLC stamp (taken as the sender's session put
it), per link, from the start word on (transport.link_stats).  All processes run on one
host and read one clock, so this is a one-way figure, not half a round trip.  The bench
reads each follower's final counters from launch.json:
  nbr_lat_p50_us / nbr_lat_p99_us: over all of that follower's neighbour links.
Per run it prints the median over followers of p50 and of p99, and the worst follower.

Scenarios: a ring of n followers (ring<n>, generated into the output directory like
ring16: the paper's gains, two targets each observed by half the ring), or with
`--shipped` the shipped scenarios as they are (ring32 with its one-thread Zenoh runtime and
velocity stage: what `enclose run ring32` runs).

Run: python bench/bench_latency.py [--sizes 8 32] [--shipped ring32] [--repeats 3]
     [--duration 20] [--out runs/bench-latency]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Any

GAINS = '[gains]\nk_e = 6.0\nalpha1 = "7/3"\nk_z = 2.0\nalpha2 = 3.0\nk_d = 2.0\nalpha3 = 3.0\n'


def ring_scenario(n: int, duration_s: float) -> str:
    """A ring of n followers on a 20-30 m annulus, as ring16 is built."""
    angle = 360.0 / n
    lines = [f'name = "ring{n}"', "beta_m_s = 1.118033988749895", "",
             "[pattern]", "rho_d_m = 8.0", "w_d_rad_s = 0.2",
             f"angles_deg = [{', '.join([f'{angle:.6f}'] * n)}]", "", GAINS,
             "[graph]",
             f"edges = [{', '.join(f'[{i + 1}, {(i + 1) % n + 1}]' for i in range(n))}]",
             "", "[run]", f"duration_s = {duration_s}", "dt_s = 0.001", "rate_hz = 50.0", ""]
    for i in range(n):
        th = 2 * math.pi * i / n
        r = 20.0 + 10.0 * ((i * 7) % 5) / 4.0
        lines += ["[[followers]]", f"pos_m = [{r * math.cos(th):.2f}, {r * math.sin(th):.2f}]"]
    half = n // 2
    first = ", ".join(str(i + 1) for i in range(half))
    second = ", ".join(str(i + 1) for i in range(half, n))
    lines += ["", "[[targets]]", "pos_m = [0.0, 0.0]", 'profile = "paper_v1"',
              f"observed_by = [{first}]", "", "[[targets]]", "pos_m = [1.0, 1.0]",
              'profile = "paper_v2"', f"observed_by = [{second}]", ""]
    return "\n".join(lines)


def run_once(scenario: Path | str, duration_s: float, out: Path,
             extra: list[str]) -> dict[str, Any]:
    argv = [sys.executable, "-m", "deploy.cli", "run", str(scenario), "--duration",
            str(duration_s), "--out", str(out), "--latency-stamps", *extra]
    code = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                          check=False).returncode
    try:
        status = json.loads((out / "launch.json").read_text())["status"]
    except (OSError, ValueError, KeyError) as exc:  # the run did not get far: say so, go on
        return {"exit_code": code, "followers_reporting": 0, "error": f"{exc} (see {out}/logs)"}
    fol = {k: v for k, v in status.items() if k.startswith("follower") and "nbr_lat_p50_us" in v}
    p50 = [v["nbr_lat_p50_us"] for v in fol.values()]
    p99 = [v["nbr_lat_p99_us"] for v in fol.values()]
    if not fol:
        return {"exit_code": code, "followers_reporting": 0}
    return {
        "exit_code": code,
        "followers_reporting": len(fol),
        "samples": sum(v["nbr_lat_n"] for v in fol.values()),
        "p50_us_median_follower": statistics.median(p50),
        "p50_us_worst_follower": max(p50),
        "p99_us_median_follower": statistics.median(p99),
        "p99_us_worst_follower": max(p99),
        "tick_overruns": sum(v.get("overruns", 0) for v in fol.values()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="*", type=int, default=[8, 32])
    parser.add_argument("--shipped", nargs="*", default=[], metavar="NAME",
                        help="shipped scenarios to measure as they are (e.g. ring32)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--out", type=Path, default=Path("runs/bench-latency"))
    # Any other argument goes to `enclose run` (an A/B: `--zenoh-runtime split`).
    args, extra = parser.parse_known_args()
    args.out.mkdir(parents=True, exist_ok=True)
    cases: list[tuple[str, Path | str, str]] = []  # label, scenario, run folder stem
    for n in args.sizes:
        scenario = (args.out / f"ring{n}.toml").resolve()
        scenario.write_text(ring_scenario(n, args.duration))
        cases.append((f"ring{n}", scenario, f"ring{n}"))
    cases += [(f"{name} (shipped)", name, f"{name}-shipped") for name in args.shipped]
    for label, scenario, stem in cases:
        runs = []
        for k in range(args.repeats):
            res = run_once(scenario, args.duration, (args.out / f"{stem}-{k}").resolve(), extra)
            print(f"== {label} run {k + 1} ({args.duration:g} s): {json.dumps(res)}", flush=True)
            runs.append(res)
        ok = [r for r in runs if r.get("followers_reporting")]
        for key in ("p50_us_median_follower", "p99_us_median_follower", "p99_us_worst_follower",
                    "tick_overruns"):
            vals = sorted(r[key] for r in ok)
            if vals:
                print(f"{label}: {key}: median {statistics.median(vals):g}, runs {vals}")


if __name__ == "__main__":
    main()
