"""Accuracy and speed of the lock-step core on the paper's case (issue: core).

Prints the figures BENCHMARKS.md quotes:
  - 200 s at dt = 1 ms: metrics and integration wall time (best of --repeat runs compiled,
    one interpreted)
  - 200 s at dt = 20 ms (50 Hz): metrics
  - a table over loop rates for the step-limited discretisation and the plain
    explicit Euler of the paper's law, against the paper's bounds.

Run: python bench/bench_core.py [--repeat 2] [--duration 200]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from agents.analysis.metrics import Metrics, compute_metrics, error_series
from agents.loading.scenario_file import load_scenario
from agents.lockstep.engine import simulate_lockstep
from agents.scenario.model import Scenario

EPS_RHO_M, EPS_DELTA = 0.0999, 0.0199
RATES_HZ = (1000.0, 100.0, 50.0, 20.0, 10.0, 5.0, 2.0)


def run(
    scenario: Scenario, dt_s: float, duration_s: float, engine: str = "auto"
) -> tuple[Metrics, float]:
    start = time.perf_counter()
    series = simulate_lockstep(scenario, dt_s, duration_s, engine=engine)
    wall = time.perf_counter() - start
    angles = np.asarray(scenario.pattern.angles_rad)
    errors = error_series(series, scenario.successor, angles, scenario.pattern.rho_d_m)
    return compute_metrics(series, errors, duration_s / 2.0, EPS_RHO_M, EPS_DELTA), wall


def with_fraction(scenario: Scenario, fraction: float) -> Scenario:
    return dataclasses.replace(
        scenario, gains=dataclasses.replace(scenario.gains, step_fraction=fraction)
    )


def fmt(value: float | None) -> str:
    return "never" if value is None else f"{value:.3g}"


def row(label: str, rate_hz: float, m: Metrics) -> str:
    ok = (
        m.estimator_error_m < EPS_RHO_M
        and m.radius_error_m < EPS_RHO_M
        and m.angle_error < EPS_DELTA
    )
    cells = [
        label,
        f"{rate_hz:g}",
        fmt(m.estimator_error_m),
        fmt(m.radius_error_m),
        fmt(m.angle_error),
        fmt(m.settle_time_s),
        fmt(m.command_jump_m_s),
        "yes" if ok else "NO",
    ]
    return "| " + " | ".join(cells) + " |"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--repeat", type=int, default=2, help="runs of the 1 ms case (best wall time)"
    )
    parser.add_argument("--duration", type=float, default=200.0)
    args = parser.parse_args()
    paper = load_scenario()

    # The interpreted engine (the same law, no numba) is slow: one run is enough to say how.
    for engine, repeat in (("numba", args.repeat), ("python", 1)):
        walls = []
        for _ in range(max(1, repeat)):
            m1, wall = run(paper, 0.001, args.duration, engine)
            walls.append(wall)
        runs = ", ".join(f"{w:.2f}" for w in walls)
        print(
            f"dt = 1 ms, {args.duration:g} s, engine {engine}: best wall {min(walls):.2f} s "
            f"(runs: {runs}; a first numba run compiles unless cached); target <= 4 s"
        )
        print(f"  {m1.as_dict()}")
    m20, _ = run(paper, 0.02, args.duration)
    print(f"dt = 20 ms: {m20.as_dict()}")

    print(
        "\n| discretisation | rate [Hz] | estimator_error_m | radius_error_m | angle_error "
        "| settle_time_s | command_jump_m_s | within paper bounds |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for label, fraction in (("step-limited (default)", 0.5), ("plain Euler", 0.0)):
        scenario = with_fraction(paper, fraction)
        for rate in RATES_HZ:
            m = (
                m1
                if (rate == 1000.0 and fraction == 0.5)
                else run(scenario, 1.0 / rate, args.duration)[0]
            )
            print(row(label, rate, m), flush=True)


if __name__ == "__main__":
    main()
