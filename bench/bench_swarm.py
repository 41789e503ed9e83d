"""The networked swarm on loopback (issue: swarm): accuracy, timing, load, memory.

Runs `enclose run` as a real multi-process swarm for each case and prints:
  metrics (estimator, radius, angle errors, settle time, command jump),
  neighbour-state age at use (p50, p99 over followers), loop tick overruns,
  RSS per follower (max over the run), and the time from the command to all
  processes linked.

Run: python bench/bench_swarm.py [--duration 120] [--cases paper ring16 ring32]
     [--estimators paper robust] [--out runs/bench-swarm]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from deploy.procs.pids import read_pids
from deploy.report.cpu_load import process_cpu_s, process_status_kb


def rss_mb(pid: int) -> float | None:
    kb = process_status_kb(pid, "VmRSS")
    return None if kb is None else kb / 1024.0


def run_case(scenario: str, duration_s: float, out: Path, estimator: str) -> dict[str, Any]:
    argv = [
        sys.executable,
        "-m",
        "deploy.cli",
        "run",
        scenario,
        "--duration",
        str(duration_s),
        "--out",
        str(out),
        "--estimator",
        estimator,
    ]
    t_command = time.time()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    peak: dict[str, float] = {}
    cpu: dict[str, float] = {}
    try:
        while proc.poll() is None:
            for name, ident in read_pids(out / "logs").items():
                if name.startswith("follower"):
                    rss = rss_mb(ident.pid)
                    if rss is not None:
                        peak[name] = max(peak.get(name, 0.0), rss)
                used = process_cpu_s(ident.pid)
                if used is not None:  # the last reading before the process ends
                    cpu[name] = used
            time.sleep(1.0)
    finally:
        if proc.poll() is None:
            proc.kill()
    launch = json.loads((out / "launch.json").read_text())
    metrics = json.loads((out / "metrics.json").read_text())
    followers = {k: v for k, v in launch["status"].items() if k.startswith("follower")}
    return {
        "exit_code": proc.returncode,
        "metrics": {
            k: metrics[k]
            for k in (
                "estimator_error_m",
                "radius_error_m",
                "angle_error",
                "settle_time_s",
                "command_jump_m_s",
            )
        },
        "command_to_linked_s": launch.get("linked_wall_s", t_command) - t_command,
        "nbr_age_p50_ms": max(f.get("nbr_age_p50_us", 0) for f in followers.values()) / 1000.0,
        "nbr_age_p99_ms": max(f.get("nbr_age_p99_us", 0) for f in followers.values()) / 1000.0,
        "overruns_total": sum(f.get("overruns", 0) for f in followers.values()),
        "ticks_per_follower": duration_s * 50.0,
        "rss_follower_mb_max": max(peak.values()) if peak else None,
        "rss_follower_mb_mean": sum(peak.values()) / len(peak) if peak else None,
        "followers": len(followers),
        # Whole-process CPU over its life (take-off and start-up included), % of one core.
        "cpu_pct_of_core": {k: round(100.0 * v / (time.time() - t_command), 1)
                            for k, v in sorted(cpu.items())},
        "states_sent_per_s_per_follower": sum(f.get("states_sent", 0) for f in
                                              followers.values()) / len(followers) / duration_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--duration", type=float, default=120.0)
    parser.add_argument("--cases", nargs="+", default=["paper", "ring16"])
    parser.add_argument("--out", type=Path, default=Path("runs/bench-swarm"))
    parser.add_argument("--estimators", nargs="+", default=["paper", "robust"])
    args = parser.parse_args()
    for case in args.cases:
        for estimator in args.estimators:
            out = (args.out / f"{case}-{estimator}").resolve()
            result = run_case(case, args.duration, out, estimator)
            print(f"== {case}, {estimator} estimator ({args.duration:g} s, 50 Hz, loopback): {out}")
            print(json.dumps(result, indent=2), flush=True)


if __name__ == "__main__":
    main()
