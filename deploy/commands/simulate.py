"""`enclose simulate`: a scenario's closed loop integrated in lock-step, no network.

The paper's law runs in its compiled engine (agents.lockstep.engine); any other law, or the
paper's with --through-interface, through the law interface (agents.lockstep.any_law).
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from agents.analysis.timeseries import RunSeries
from agents.loading.law_loader import make_law
from agents.loading.scenario_file import load_scenario
from agents.lockstep.any_law import simulate_law
from agents.lockstep.engine import ENGINES, simulate_lockstep
from agents.scenario.model import Scenario
from agents.shell.law_args import LawOptions, add_law_arguments, apply_law_arguments
from agents.shell.weather_args import (
    WeatherOptions,
    add_weather_arguments,
    apply_weather_arguments,
)
from deploy.launch.launch_options import add_figures_argument
from deploy.report.run_report import write_run_outputs
from deploy.report.rundir import RunInfo
from deploy.report.verdict import add_json_argument, announce
from errors import ScenarioError

log = logging.getLogger(__name__)


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "simulate", help="lock-step simulation of a scenario (no network): metrics, CSV, figures"
    )
    parser.add_argument(
        "scenario",
        nargs="?",
        default=None,
        help="scenario TOML file or shipped name (default: the paper's case)",
    )
    parser.add_argument(
        "--dt", type=float, default=None, help="step in seconds (default: scenario)"
    )
    parser.add_argument("--duration", type=float, default=None, help="seconds (default: scenario)")
    parser.add_argument(
        "--out", type=Path, default=None, help="run directory (default: runs/simulate-<name>)"
    )
    parser.add_argument(
        "--engine",
        choices=ENGINES,
        default="auto",
        help="numba: the law compiled into the loop (default when installed); python: the "
             "same functions interpreted (slow)",
    )
    parser.add_argument(
        "--estimator-dt", type=float, default=None,
        help="estimator step in seconds, dividing --dt (default: the scenario's "
             "estimator_rate_hz, as the followers run it; --dt if that is coarser)",
    )
    parser.add_argument(
        "--through-interface", action="store_true",
        help="run the paper's law through the law interface, as any other law runs, "
             "instead of its compiled engine",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_figures_argument(parser)
    add_json_argument(parser)
    add_law_arguments(parser)
    add_weather_arguments(parser)
    parser.set_defaults(func=_main)


class ProgressBar:
    """A one-line progress bar on stderr, only when stderr is a terminal."""

    def __init__(self, label: str, enabled: bool) -> None:
        self._label, self._enabled = label, enabled and sys.stderr.isatty()
        self._start = time.monotonic()

    def __call__(self, fraction: float) -> None:
        if not self._enabled:
            return
        elapsed = time.monotonic() - self._start
        eta = elapsed * (1.0 - fraction) / fraction if fraction > 0 else 0.0
        bar = "#" * int(30 * fraction)
        sys.stderr.write(f"\r{self._label} [{bar:<30}] {100 * fraction:5.1f}% eta {eta:4.1f}s")
        if fraction >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()


@dataclass(frozen=True)
class SimulateOptions:
    """`enclose simulate`'s command line (None: the scenario's value)."""

    scenario: str | None = None
    dt_s: float | None = None
    duration_s: float | None = None
    out: Path | None = None  # None: runs/simulate-<name>
    engine: str = "auto"
    estimator_dt_s: float | None = None  # None: the scenario's estimator rate
    progress: bool = True
    json: bool = False
    law: LawOptions = field(default_factory=LawOptions)  # --law, --law-param
    through_interface: bool = False  # the paper's law through the interface too
    figures: bool = True
    weather: WeatherOptions = field(default_factory=WeatherOptions)  # --wind, --gust, ...

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> SimulateOptions:
        return cls(args.scenario, args.dt, args.duration, args.out, args.engine,
                   args.estimator_dt, not args.no_progress, args.json,
                   LawOptions.from_namespace(args), args.through_interface,
                   not args.no_figures, WeatherOptions.from_namespace(args))


def _main(args: argparse.Namespace) -> int:
    return simulate(SimulateOptions.from_namespace(args))


def simulate(opts: SimulateOptions) -> int:
    scenario = apply_law_arguments(load_scenario(opts.scenario), opts.law)
    scenario = apply_weather_arguments(scenario, opts.weather)
    dt = scenario.run.dt_s if opts.dt_s is None else opts.dt_s
    duration = scenario.run.duration_s if opts.duration_s is None else opts.duration_s
    if not 0.0 < dt < duration:
        raise ScenarioError("--dt", f"must satisfy 0 < dt < duration ({duration} s), got {dt}")
    est_dt = opts.estimator_dt_s
    if est_dt is None:  # the followers' estimator rate, in whole steps of dt
        est_dt = dt / max(1, round(dt * scenario.run.estimator_hz))
    out = opts.out or Path("runs") / f"simulate-{scenario.name}"
    log.info(
        "simulating %s: n=%d m=%d dt=%g s estimator dt=%g s duration=%g s",
        scenario.name,
        scenario.n,
        scenario.m,
        dt,
        est_dt,
        duration,
    )
    start = time.perf_counter()
    bar = ProgressBar("simulate", opts.progress)
    try:
        series, law_extra = _integrate(scenario, opts, dt, duration, est_dt, bar)
    except ValueError as exc:
        raise ScenarioError("--estimator-dt", str(exc)) from exc
    wall = time.perf_counter() - start
    info = RunInfo.from_scenario(scenario, "lockstep", duration)
    extra = {"dt_s": dt, "estimator_dt_s": est_dt, "engine": opts.engine,
             "integration_wall_s": wall, **law_extra}
    write_run_outputs(out, series, info, extra, figures=opts.figures)
    log.info("integration took %.2f s wall; outputs in %s", wall, out)
    announce(out.resolve(), f"enclose simulate {scenario.name}", opts.json)
    return 0


def _integrate(scenario: Scenario, opts: SimulateOptions, dt: float, duration: float,
               est_dt: float, bar: ProgressBar) -> tuple[RunSeries, dict[str, Any]]:
    """The series, by the paper's compiled engine or through the law interface, and what
    metrics.json says of the law."""
    if scenario.law.is_paper and not opts.through_interface:
        series = simulate_lockstep(scenario, dt, duration, bar, opts.engine, est_dt)
        return series, {"law": scenario.law.ref, "law_path": "compiled"}
    # Lock-step commands act at once: no delay for a law to lead (Gains.lead_s).
    law = make_law(replace(scenario, gains=replace(scenario.gains, lead_s=0.0)))
    run = simulate_law(scenario, law, dt, duration, bar, est_dt)
    if run.law_failures:
        log.warning("the law failed %d times (its vehicle held each time)", run.law_failures)
    return run.series, {"law": scenario.law.ref, "law_path": "interface",
                        "law_failures": run.law_failures}
