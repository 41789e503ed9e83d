"""A bigger step share instead of more messages? ring16's lag against `[gains] step_fraction`.

Prints, for each step_fraction, the errors over the second half of
  - the lock-step loop at 50 Hz with the estimator at each of --rates (agents.lockstep.engine);
  - the networked follower logic in lock-step with every message --delays ticks late
    (tests/swarm_harness.run_swarm, robust estimator), as between processes.
The command jump column is what tells a stable step from an oscillating one.  By default
it studies the paper's first-order estimator (`robust`, order 1, whatever the scenario
ships); --order 2 adds the velocity stage, as ring16 and ring32 ship.  The rings set
their estimator's share apart (`estimator_step_fraction`), so use --estimator-only to
move the estimator's share there.

Run: python bench/bench_step_fraction.py [--case ring16] [--fractions 0.5 0.7 0.8 0.9]
     [--rates 50 100] [--delays 1 3] [--duration 120] [--order 1|2]   (a few minutes;
     ring32 with --delays: ~2 min per fraction and delay)
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agents.analysis.metrics import Metrics, compute_metrics, error_series
from agents.analysis.timeseries import RunSeries
from agents.loading.scenario_file import load_scenario
from agents.lockstep.engine import simulate_lockstep
from agents.scenario.model import Scenario
from tests.swarm_harness import run_swarm, with_estimator

EPS_M, EPS_DELTA = 0.0999, 0.0199


def metrics(scenario: Scenario, series: RunSeries, duration_s: float) -> Metrics:
    angles = np.asarray(scenario.pattern.angles_rad)
    errors = error_series(series, scenario.successor, angles, scenario.pattern.rho_d_m)
    return compute_metrics(series, errors, duration_s / 2.0, EPS_M, EPS_DELTA)


def row(label: str, m: Metrics) -> str:
    return (f"| {label} | {m.estimator_error_m:.4f} | {m.radius_error_m:.4f} | "
            f"{m.angle_error:.4f} | {m.command_jump_m_s:.3f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--case", default="ring16")
    parser.add_argument("--fractions", type=float, nargs="+", default=[0.5, 0.7, 0.8, 0.9])
    parser.add_argument("--rates", type=float, nargs="+", default=[50.0, 100.0])
    parser.add_argument("--delays", type=int, nargs="+", default=[1, 3])
    parser.add_argument("--duration", type=float, default=120.0)
    parser.add_argument("--order", type=int, choices=(1, 2), default=1,
                        help="estimator order: 1, the paper's first-order law (default); 2, "
                             "with the velocity stage (as ring16 and ring32 ship)")
    parser.add_argument("--estimator-only", action="store_true",
                        help="vary [gains] estimator_step_fraction, the controller's share "
                             "staying at the scenario's step_fraction")
    args = parser.parse_args()
    field = "estimator_step_fraction" if args.estimator_only else "step_fraction"
    base = with_estimator(load_scenario(args.case), "robust2" if args.order == 2 else "robust")
    print("| run | estimator_error_m | radius_error_m | angle_error | command_jump_m_s |")
    print("|---|---|---|---|---|")
    for fraction in args.fractions:
        s = dataclasses.replace(base, gains=dataclasses.replace(base.gains,
                                                                **{field: fraction}))
        for rate in args.rates:
            series = simulate_lockstep(s, 0.02, args.duration, estimator_dt_s=1.0 / rate)
            print(row(f"{field} {fraction:g}, lock-step, estimator {rate:g} Hz",
                      metrics(s, series, args.duration)), flush=True)
        for delay in args.delays:
            series = run_swarm(s, args.duration, delay_ticks=delay)
            print(row(f"{field} {fraction:g}, data {delay} tick(s) late, 50 Hz",
                      metrics(s, series, args.duration)), flush=True)


if __name__ == "__main__":
    main()
