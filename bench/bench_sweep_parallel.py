"""Parallel sweeps against a sequential one: the same 8 cells (bench/sweeps/loss_delay.toml,
same seeds) run one at a time, with `--jobs 2`, and on a local two-worker Dask cluster.

Prints the wall time and speed-up of each, checks that the three tables have the same
structure and statuses, and reports how far their metrics differ from the sequential
ones (parallel cells share the CPU, so they are not expected to match exactly).

    python bench/bench_sweep_parallel.py [--duration 30] [--out runs/bench-sweep-parallel]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SWEEP = ROOT / "bench" / "sweeps" / "loss_delay.toml"
METRICS = ("estimator_error_m", "radius_error_m", "angle_error", "settle_time_s",
           "command_jump_m_s", "delivered_ratio")
RUN_COLUMNS = ("wall_s", "jobs", "load_1min", "host")


def sweep_file(folder: Path, duration_s: float) -> Path:
    """loss_delay.toml with its own out folder and duration."""
    text = SWEEP.read_text()
    text = re.sub(r"(?m)^duration_s = .*$", f"duration_s = {duration_s:g}", text)
    text = re.sub(r"(?m)^out = .*$", 'out = "out"', text)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "sweep.toml"
    path.write_text(text)
    return path


def run(path: Path, *extra: str) -> float:
    """`enclose sweep` from scratch; its wall time."""
    shutil.rmtree(path.parent / "out", ignore_errors=True)
    argv = [sys.executable, "-m", "deploy.cli", "sweep", str(path), *extra]
    t0 = time.monotonic()
    done = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, check=False)
    wall = time.monotonic() - t0
    (path.parent / "sweep.log").write_text(done.stdout + done.stderr)
    if done.returncode != 0:
        print(f"warning: {' '.join(argv[3:])} exited {done.returncode}", file=sys.stderr)
    return wall


def table(path: Path) -> list[dict[str, str]]:
    with open(path.parent / "out" / "results.csv", newline="") as f:
        return list(csv.DictReader(f))


def structure(rows: list[dict[str, str]]) -> list[list[tuple[str, str]]]:
    """Each row without its metrics and run columns: cell, grid values, seed, status."""
    return [[(k, v) for k, v in r.items() if k not in (*METRICS, *RUN_COLUMNS)] for r in rows]


def differences(base: list[dict[str, str]], other: list[dict[str, str]]) -> dict[str, float]:
    """Per metric, the largest |other - base| over the cells where both have a value."""
    out = {}
    for m in METRICS:
        pairs = [(float(a[m]), float(b[m])) for a, b in zip(base, other, strict=True)
                 if a.get(m) and b.get(m)]
        if pairs:
            out[m] = max(abs(b - a) for a, b in pairs)
    return out


def mean_load(rows: list[dict[str, str]]) -> float:
    return statistics.fmean([float(r["load_1min"]) for r in rows if r.get("load_1min")] or [0])


def on_cluster(path: Path) -> float:
    import dask
    from distributed import LocalCluster

    with dask.config.set({"temporary-directory": str(path.parent / "dask")}), LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
        dashboard_address=None,
    ) as cluster:
        return run(path, "--cluster", cluster.scheduler_address)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=30.0, help="seconds of each run")
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "bench-sweep-parallel")
    args = ap.parse_args()
    out = args.out.resolve()
    modes = {name: sweep_file(out / name, args.duration) for name in ("seq", "jobs2", "cluster")}
    walls = {
        "seq": run(modes["seq"]),
        "jobs2": run(modes["jobs2"], "--jobs", "2"),
        "cluster": on_cluster(modes["cluster"]),
    }
    tables = {name: table(path) for name, path in modes.items()}
    base = tables["seq"]
    print(f"8 cells of {args.duration:g} s, {os.cpu_count()} cores, "
          f"load average at the end {os.getloadavg()[0]:.1f}")
    print("| mode | wall_s | speed-up | cells done | same cells and statuses as seq | "
          "mean load_1min | largest metric difference from seq |")
    print("|---|---|---|---|---|---|---|")
    report = {}
    for name, rows in tables.items():
        same = structure(rows) == structure(base)
        diff = differences(base, rows) if name != "seq" else {}
        done = sum(r["status"] == "done" for r in rows)
        shown = ", ".join(f"{k} {v:.3g}" for k, v in diff.items()) or "-"
        print(f"| {name} | {walls[name]:.0f} | {walls['seq'] / walls[name]:.2f} | {done}/8 | "
              f"{'yes' if same else 'NO'} | {mean_load(rows):.1f} | {shown} |")
        report[name] = {"wall_s": walls[name], "speed_up": walls["seq"] / walls[name],
                        "done": done, "same_structure": same, "max_abs_diff": diff,
                        "mean_load_1min": mean_load(rows)}
    (out / "bench.json").write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
