"""Repeatability (issue 9): the main job N times, against the lock-step run at its control rate.

Runs `enclose run --duration D` with the defaults N times (real processes on loopback),
then `enclose simulate` once at the scenario's control rate (`--dt` = 1 / rate_hz), and
prints every run's metrics, the distribution (min / median / max) and the issue's checks:
every run inside the paper's bounds, worst estimator error <= 1.5x the lock-step one,
command jump < 0.5 m/s.  Simulator overruns and catch-ups come from launch.json (the
simulator's status as the flight ended).

Each run also reports its cost (launch.json "load"): the share of follower ticks that ran
late, the simulator's late ticks, the followers' mean CPU, the largest follower's peak RSS
over the run and how busy the machine was: a run on a saturated machine measures the
machine, not the design.

Run (idle machine, about 24 min with the defaults):
    python bench/bench_repeat.py [--scenario ring32] [--runs 10] [--duration 120]
        [--out runs/bench-repeat] [-- extra enclose run arguments, e.g. --estimator paper]
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

from agents.loading.scenario_file import load_scenario

KEYS = ("estimator_error_m", "radius_error_m", "angle_error", "settle_time_s",
        "command_jump_m_s", "silent_followers")
EPS_M, EPS_DELTA = 0.0999, 0.0199


def metrics(out: Path) -> dict[str, Any]:
    return json.loads((out / "metrics.json").read_text())


def swarm_run(out: Path, scenario: str, duration_s: float, extra: list[str]) -> dict[str, Any]:
    shutil.rmtree(out, ignore_errors=True)
    argv = [sys.executable, "-m", "deploy.cli", "run", scenario, "--duration", str(duration_s),
            "--out", str(out), "--no-live", *extra]
    code = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                          check=False).returncode
    result = {k: metrics(out).get(k) for k in KEYS} if (out / "metrics.json").exists() else {}
    sim: dict[str, Any] = {}
    cost: dict[str, Any] = {}
    if (out / "launch.json").exists():
        launch = json.loads((out / "launch.json").read_text())
        # As the flight ended: after it, every vehicle whose follower stopped fails safe.
        sim = (launch.get("status_at_stop") or launch["status"]).get("sim-0", {})
        cost = load_figures(launch.get("load") or {})
    return {"exit_code": code, **result, **cost,
            **{k: sim.get(k) for k in ("overruns", "catch_ups", "caught_up_ticks", "failsafes")}}


def load_figures(load: dict[str, Any]) -> dict[str, Any]:
    """Late ticks, CPU and the largest follower's peak RSS over the whole run, from
    launch.json "load" (deploy.report.cpu_load)."""
    ticks = load.get("ticks") or {}
    cpu = load.get("process_cpu_pct") or {}
    followers = [v for k, v in cpu.items() if k.startswith("follower-")]
    rss = [v for k, v in (load.get("process_peak_rss_mb") or {}).items()
           if k.startswith("follower-")]
    return {"late_pct": ticks.get("overrun_pct"), "sim_late_pct": ticks.get("sim_overrun_pct"),
            "follower_cpu_pct": float(np.mean(followers)) if followers else None,
            "follower_rss_mb": float(max(rss)) if rss else None,
            "busy_pct": load.get("machine_busy_pct")}


def lockstep(out: Path, scenario: str, duration_s: float, rate_hz: float) -> dict[str, Any]:
    shutil.rmtree(out, ignore_errors=True)
    subprocess.run([sys.executable, "-m", "deploy.cli", "simulate", scenario,
                    "--dt", f"{1 / rate_hz}", "--duration", str(duration_s), "--out", str(out),
                    "--no-progress"],
                   stdout=subprocess.DEVNULL, check=True)
    return {k: metrics(out).get(k) for k in KEYS}


def inside(r: dict[str, Any]) -> bool:
    return (r.get("exit_code") == 0 and not r.get("silent_followers")
            and (r.get("estimator_error_m") or 1.0) < EPS_M
            and (r.get("radius_error_m") or 1.0) < EPS_M
            and (r.get("angle_error") or 1.0) < EPS_DELTA)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="paper", help="shipped name or TOML file")
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--duration", type=float, default=120.0)
    parser.add_argument("--out", type=Path, default=Path("runs/bench-repeat"))
    parser.add_argument("extra", nargs="*", help="more `enclose run` arguments (after --)")
    args = parser.parse_args()
    # The reference at the swarm's own control rate (ring64: 20 Hz), not a fixed 50 Hz.
    rate_hz = load_scenario(args.scenario).run.rate_hz
    ref = lockstep((args.out / f"lockstep-{rate_hz:g}hz").resolve(), args.scenario,
                   args.duration, rate_hz)
    cols = [*KEYS, "late_pct", "sim_late_pct", "follower_cpu_pct", "follower_rss_mb", "busy_pct",
            "overruns",
            "catch_ups", "failsafes"]
    print("| run | exit | " + " | ".join(cols) + " |")
    print("|---|---|" + "---|" * len(cols), flush=True)
    runs = []
    for k in range(args.runs):
        r = swarm_run((args.out / f"run-{k + 1}").resolve(), args.scenario, args.duration,
                      args.extra)
        runs.append(r)
        print(f"| {k + 1} | {r['exit_code']} | " +
              " | ".join(f"{r.get(c):.4g}" if isinstance(r.get(c), float) else str(r.get(c))
                         for c in cols) + " |", flush=True)
    print(f"| lock-step {rate_hz:g} Hz | | "
          + " | ".join(f"{ref[c]:.4g}" if isinstance(ref.get(c), float) else str(ref.get(c))
                       for c in KEYS) + " |")
    print("\n| metric | min | median | max |\n|---|---|---|---|")
    for c in (*KEYS, "late_pct", "sim_late_pct", "follower_cpu_pct", "follower_rss_mb",
              "busy_pct"):
        vals = np.array([r[c] for r in runs if isinstance(r.get(c), float)])
        if vals.size:
            print(f"| {c} | {vals.min():.4g} | {np.median(vals):.4g} | {vals.max():.4g} |")
    worst = max((r.get("estimator_error_m") or np.inf) for r in runs)
    jump = max((r.get("command_jump_m_s") or np.inf) for r in runs)
    n_inside = sum(inside(r) for r in runs)
    late = max((r.get("late_pct") or 0.0) for r in runs)
    print(f"\n{n_inside} of {len(runs)} runs inside the paper's bounds; worst late ticks "
          f"{late:.2f} % (target < 1 %)")
    print(f"worst estimator error {worst:.4g} m = {worst / ref['estimator_error_m']:.2f}x the "
          f"lock-step run at {rate_hz:g} Hz ({ref['estimator_error_m']:.4g} m); target <= 1.5x")
    print(f"largest command jump {jump:.3g} m/s; target < 0.5 m/s")


if __name__ == "__main__":
    main()
