"""`enclose simulate`: the paper's closed loop integrated in lock-step, no network."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path
from typing import Any

from agents.core.lockstep import ENGINES, simulate_lockstep
from agents.scenario.file import load_scenario
from deploy.report import write_run_outputs
from deploy.rundir import RunInfo
from deploy.verdict import add_json_argument, announce
from transport.errors import ScenarioError

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
        help="numba: compiled loop (default when installed); numpy: reference functions",
    )
    parser.add_argument(
        "--estimator-dt", type=float, default=None,
        help="estimator step in seconds, dividing --dt (default: the scenario's "
             "estimator_rate_hz, as the followers run it; --dt if that is coarser)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_json_argument(parser)
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


def _main(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    dt = scenario.run.dt_s if args.dt is None else args.dt
    duration = scenario.run.duration_s if args.duration is None else args.duration
    if not 0.0 < dt < duration:
        raise ScenarioError("--dt", f"must satisfy 0 < dt < duration ({duration} s), got {dt}")
    est_dt = args.estimator_dt
    if est_dt is None:  # the followers' estimator rate, in whole steps of dt
        est_dt = dt / max(1, round(dt * scenario.run.estimator_hz))
    out = args.out or Path("runs") / f"simulate-{scenario.name}"
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
    bar = ProgressBar("simulate", not args.no_progress)
    try:
        series = simulate_lockstep(scenario, dt, duration, bar, args.engine, est_dt)
    except ValueError as exc:
        raise ScenarioError("--estimator-dt", str(exc)) from exc
    wall = time.perf_counter() - start
    info = RunInfo.from_scenario(scenario, "lockstep", duration)
    extra = {"dt_s": dt, "estimator_dt_s": est_dt, "engine": args.engine,
             "integration_wall_s": wall}
    write_run_outputs(out, series, info, extra)
    log.info("integration took %.2f s wall; outputs in %s", wall, out)
    announce(out.resolve(), f"enclose simulate {scenario.name}", args.json)
    return 0
