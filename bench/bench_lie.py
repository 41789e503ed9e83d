"""A lying follower in the paper case (issue 51, item 1): what the others suffer, and when
they name it.

    .venv/bin/python bench/bench_lie.py [--modes offset,bound,walk,stale] [--at 20]
        [--lie 30] [--duration 60] [--liar 2] [--runs 1] [--out /tmp/bench-lie]
    .venv/bin/python bench/bench_lie.py --analyse RUN_DIR [--at 20 --lie 30 --liar 2]

Each run is `enclose run paper --fault AT:lie:follower-LIAR:LIE:MODE`.  Per run, over the
honest followers only (the liar's own published estimate is a lie by construction):
their largest estimator error |r_i - LAP| and radius error |e_rho| during the lie, the
time after the lie ends until their estimator, radius and angle errors are all back
under the paper's bounds for good, the largest errors from 10 s after the lie's end,
the closest approach of any two vehicles, and when each neighbour first rejected the
liar (its status counters `implausible_first_ms_f<j>`).  One JSON line per run.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

from deploy.verdict import read_verdict

BOUNDS = {"est": 0.0999, "e_rho": 0.0999, "e_delta": 0.0199}
ENCLOSE = str(Path(sys.executable).with_name("enclose"))


def _rows(run_dir: Path) -> list[dict[str, float]]:
    with (run_dir / "series.csv").open() as f:
        return [{k: float(v) for k, v in row.items() if v not in ("", None)}
                for row in csv.DictReader(f)]


def _worst(row: dict[str, float], honest: list[int]) -> dict[str, float]:
    return {"est": max(abs(row.get(f"est{i}_est_err_m", math.inf)) for i in honest),
            "e_rho": max(abs(row.get(f"e{i}_e_rho_m", math.inf)) for i in honest),
            "e_delta": max(abs(row.get(f"e{i}_e_delta", math.inf)) for i in honest)}


def _separation(row: dict[str, float], n: int) -> float:
    pos = [(row[f"f{i}_x_m"], row[f"f{i}_y_m"]) for i in range(1, n + 1)]
    return min(math.dist(a, b) for k, a in enumerate(pos) for b in pos[k + 1:])


def analyse(run_dir: Path, at_s: float, lie_s: float, liar: int) -> dict[str, Any]:
    """The figures of one run (module docstring); `liar` 1-based."""
    rows = _rows(run_dir)
    n = sum(1 for k in rows[0] if k.startswith("est"))
    honest = [i for i in range(1, n + 1) if i != liar]
    end = at_s + lie_s
    during = [_worst(r, honest) for r in rows if at_s <= r["t_s"] < end]
    after = [(r["t_s"], _worst(r, honest)) for r in rows if r["t_s"] >= end]
    outside = [t for t, w in after if any(w[k] >= BOUNDS[k] for k in BOUNDS)]
    back_s = (max(outside) - end if outside else 0.0) if after else None
    late = [w for t, w in after if t >= end + 10.0]
    launch = json.loads((run_dir / "launch.json").read_text())
    status = launch.get("status_at_stop") or launch.get("status") or {}
    key = f"implausible_first_ms_f{liar - 1}"
    detected = {name: c[key] / 1000.0 for name, c in status.items() if key in c}
    liars = read_verdict(run_dir, "bench").liars
    return {
        "run": str(run_dir),
        "during_est_max_m": max((w["est"] for w in during), default=None),
        "during_e_rho_max_m": max((w["e_rho"] for w in during), default=None),
        "back_inside_after_s": back_s,
        "after10_est_max_m": max((w["est"] for w in late), default=None),
        "after10_e_rho_max_m": max((w["e_rho"] for w in late), default=None),
        "after10_e_delta_max": max((w["e_delta"] for w in late), default=None),
        "min_separation_m": min(_separation(r, n) for r in rows),
        "detected_s": detected,
        "detection_delay_s": (min(detected.values()) - at_s) if detected else None,
        "rejected": {name: c.get(f"implausible_f{liar - 1}", 0) for name, c in status.items()
                     if name.startswith("follower-")},
        "verdict_liars": list(liars),
        "verdict_names_liar": any(line.startswith(f"follower-{liar - 1} ") and " lied:" in line
                                  for line in liars),
    }


def run_one(mode: str, args: argparse.Namespace, k: int) -> Path:
    out = Path(args.out) / f"{mode}-{k}"
    fault = f"{args.at:g}:lie:follower-{args.liar}:{args.lie:g}:{mode}"
    subprocess.run([ENCLOSE, "run", "paper", "--duration", f"{args.duration:g}", "--no-live",
                    "--no-figures", "--fault", fault, "--out", str(out)],
                   capture_output=True, check=False)
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--modes", default="offset,bound,walk,stale")
    p.add_argument("--at", type=float, default=20.0)
    p.add_argument("--lie", type=float, default=30.0)
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--liar", type=int, default=2, help="1-based follower number")
    p.add_argument("--runs", type=int, default=1)
    p.add_argument("--out", default="/tmp/bench-lie")
    p.add_argument("--analyse", default=None, metavar="RUN_DIR")
    args = p.parse_args()
    if args.analyse:
        print(json.dumps(analyse(Path(args.analyse), args.at, args.lie, args.liar)))
        return 0
    for mode in args.modes.split(","):
        for k in range(args.runs):
            out = run_one(mode, args, k)
            print(json.dumps({"mode": mode, **analyse(out, args.at, args.lie, args.liar)}),
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
