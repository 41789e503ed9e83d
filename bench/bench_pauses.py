"""Pauses (issue 9): role x pause length -> time back inside the paper's bounds, worst error.

For each estimator and role, one real loopback `enclose run` in which that role's
process is frozen (SIGSTOP, then SIGCONT, by PID) once per pause length, `--spacing`
seconds apart; each recovery is judged from its resume to the next pause (series.csv,
deploy.report.recovery).  Prints a markdown table.

Run (idle machine, about 12 min with the defaults):
    python bench/bench_pauses.py [--lengths 0.2 0.5 1 2 5] [--roles sim follower-0 target-0]
        [--estimators robust paper] [--first-at 15] [--spacing 15] [--out runs/bench-pauses]
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from deploy.report.recovery import recoveries
from tests.integration.pauses import Pause, run_with_pauses


def fmt(x: float | None, digits: int = 3) -> str:
    return "never" if x is None else f"{x:.{digits}g}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lengths", type=float, nargs="+", default=[0.2, 0.5, 1.0, 2.0, 5.0])
    parser.add_argument("--roles", nargs="+", default=["sim", "follower-0", "target-0"])
    parser.add_argument("--estimators", nargs="+", default=["robust", "paper"])
    parser.add_argument("--first-at", type=float, default=15.0, help="first pause [s]")
    parser.add_argument("--spacing", type=float, default=15.0, help="between pauses [s]")
    parser.add_argument("--out", type=Path, default=Path("runs/bench-pauses"))
    args = parser.parse_args()
    rows = []
    for estimator in args.estimators:
        for role in args.roles:
            plan = [Pause(args.first_at + k * args.spacing, role, length)
                    for k, length in enumerate(args.lengths)]
            duration = args.first_at + len(plan) * args.spacing
            out = (args.out / f"{estimator}-{role}").resolve()
            shutil.rmtree(out, ignore_errors=True)
            run = run_with_pauses(out, duration, plan, "--estimator", estimator)
            if run.returncode != 0 or len(run.pauses_wall_s) != len(plan):
                print(f"{estimator} {role}: run failed ({run.returncode}): {out}", flush=True)
                continue
            for pause, rec in zip(plan, recoveries(out, run.pauses_wall_s), strict=True):
                rows.append((estimator, role, pause.length_s, rec))
                print(f"{estimator} {role} {pause.length_s:g} s: {rec.as_dict()}", flush=True)
    print("\n| estimator | paused | pause [s] | back inside the bounds after [s] | worst "
          "estimator error [m] | worst radius error [m] | worst angle error |")
    print("|---|---|---|---|---|---|---|")
    for estimator, role, length, rec in rows:
        print(f"| {estimator} | {role} | {length:g} | {fmt(rec.recovered_after_s)} | "
              f"{fmt(rec.worst_estimator_m)} | {fmt(rec.worst_radius_m)} | "
              f"{fmt(rec.worst_angle)} |")


if __name__ == "__main__":
    main()
