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
import json
import subprocess
import sys
from pathlib import Path

from deploy.report.lie_window import lie_figures

ENCLOSE = str(Path(sys.executable).with_name("enclose"))


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
        print(json.dumps(lie_figures(Path(args.analyse), args.at, args.lie, args.liar)))
        return 0
    for mode in args.modes.split(","):
        for k in range(args.runs):
            out = run_one(mode, args, k)
            print(json.dumps({"mode": mode, **lie_figures(out, args.at, args.lie, args.liar)}),
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
