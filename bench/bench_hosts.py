"""The paper's case over 3 namespaced hosts (clock offsets -0.8/0/+1.3 s, 10 ms between
hosts, host 2's router restarted at 2 s) against the one-host run, several runs each.

    python bench/bench_hosts.py --runs 3 --duration 24     (root; ~1 min a run)

Prints each run's metrics and, per case, mean and spread (min-max) of the paper's
figures, plus the machine's load average (these runs are sensitive to it).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

CASES = {
    "1 host (loopback peers)": [],
    "3 hosts, offsets -0.8/0/+1.3 s, 10 ms, router-2 restart at 2 s": [
        "--hosts", "3", "--host-offsets=-0.8,0,1.3", "--host-delay-ms", "10",
        "--fault", "2:restart:router-2"],
    "3 hosts, offsets -0.8/0/+1.3 s, 10 ms": [
        "--hosts", "3", "--host-offsets=-0.8,0,1.3", "--host-delay-ms", "10"],
}
KEYS = ("estimator_error_m", "radius_error_m", "angle_error", "settle_time_s",
        "command_jump_m_s")


def one_run(extra: list[str], duration_s: float, root: Path, k: int) -> dict[str, float]:
    out = root / f"run-{k}"
    argv = [sys.executable, "-m", "deploy.cli", "run", "--duration", str(duration_s),
            "--out", str(out), "--link-timeout", "90", *extra]
    load = os.getloadavg()[0]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=600, check=False)
    if done.returncode not in (0, 3):
        print(done.stdout[-2000:], done.stderr[-2000:])
        return {"failed": 1.0, "load": load}
    metrics = json.loads((out / "metrics.json").read_text())
    row = {key: float(metrics[key]) if metrics[key] is not None else float("nan")
           for key in KEYS}
    row["load"] = load
    return row


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--duration", type=float, default=24.0)
    p.add_argument("--cases", default="0,1", help="indices into CASES, comma-separated")
    args = p.parse_args()
    names = list(CASES)
    with tempfile.TemporaryDirectory(prefix="bench-hosts-") as tmp:
        k = 0
        for idx in (int(c) for c in args.cases.split(",")):
            name = names[idx]
            rows = []
            for _ in range(args.runs):
                row = one_run(CASES[name], args.duration, Path(tmp), k)
                k += 1
                print(name, {a: round(b, 4) for a, b in row.items()}, flush=True)
                rows.append(row)
            ok = [r for r in rows if "failed" not in r]
            print(f"| {name} | {len(ok)}/{len(rows)} | " + " | ".join(
                f"{statistics.mean(r[key] for r in ok):.4g} "
                f"({min(r[key] for r in ok):.3g}-{max(r[key] for r in ok):.3g})"
                if ok else "-" for key in (*KEYS, "load")) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
