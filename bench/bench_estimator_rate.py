"""How fast must the estimator run for a long ring (issue 15)? Lock-step, control at 50 Hz.

For each scenario, k_e and estimator rate: the paper's metrics over the second half of
a 120-s lock-step run (`agents.lockstep.engine`, the estimator sub-stepped between
control steps).  Deterministic: no network, no machine load.

Run: python bench/bench_estimator_rate.py [--cases ring16 ring32] [--rates 50 100 200 400 800]
     [--k-e 6 12] [--orders 1 2]
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from agents.analysis.metrics import compute_metrics, error_series
from agents.loading.scenario_file import load_scenario
from agents.lockstep.engine import simulate_lockstep
from agents.scenario.model import Scenario

EPS_M, EPS_DELTA = 0.0999, 0.0199
CONTROL_DT_S = 0.02


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cases", nargs="+", default=["paper", "ring16", "ring32"])
    parser.add_argument("--rates", nargs="+", type=float, default=[50, 100, 200, 400, 800])
    parser.add_argument("--k-e", nargs="+", type=float, default=None,
                        help="estimator gains to try (default: the scenario's)")
    parser.add_argument("--orders", nargs="+", type=int, default=None,
                        help="estimator orders to try (1: the paper's; 2: with the velocity "
                             "stage; default: the scenario's)")
    parser.add_argument("--duration", type=float, default=120.0)
    args = parser.parse_args()
    print("| case | order | k_e | estimator Hz | estimator_error_m | radius_error_m | angle_error "
          "| settle_time_s | command_jump_m_s | inside |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.cases:
        base = load_scenario(name)
        for order in args.orders or [base.gains.estimator_order]:
            for k_e in args.k_e or [base.gains.k_e]:
                gains = dataclasses.replace(base.gains, k_e=k_e, estimator_order=order)
                s = dataclasses.replace(base, gains=gains)
                for rate in args.rates:
                    print(f"| {name} | {order} | {k_e:g} | {rate:g} | {_row(s, rate, args)}",
                          flush=True)


def _row(s: Scenario, rate_hz: float, args: argparse.Namespace) -> str:
    series = simulate_lockstep(s, CONTROL_DT_S, args.duration, estimator_dt_s=1.0 / rate_hz)
    angles = np.asarray(s.pattern.angles_rad)
    err = error_series(series, s.successor, angles, s.pattern.rho_d_m)
    m = compute_metrics(series, err, args.duration / 2, EPS_M, EPS_DELTA)
    inside = (m.estimator_error_m < EPS_M and m.radius_error_m < EPS_M
              and m.angle_error < EPS_DELTA)
    settle = "never" if m.settle_time_s is None else f"{m.settle_time_s:.2f}"
    return (f"{m.estimator_error_m:.4f} | {m.radius_error_m:.4f} | {m.angle_error:.4f} | "
            f"{settle} | {m.command_jump_m_s:.3f} | {'yes' if inside else 'NO'} |")


if __name__ == "__main__":
    main()
