"""Turn a recorded run into metrics.json, series.csv and figures: one code path for all runs."""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import Any

import numpy as np

from agents.core.metrics import Metrics, compute_metrics, error_series, window_metrics
from agents.core.timeseries import RunSeries
from deploy.figures import performance_figure, trajectory_figure
from deploy.figures_links import LINKS_PNG, link_health_figure
from deploy.marks import run_marks
from deploy.recording.link_history import LINKS_CSV, read_links_csv
from deploy.rundir import (
    METRICS_FILE,
    SERIES_FILE,
    RunInfo,
    read_info,
    read_series,
    write_metrics,
    write_series,
)
from transport.errors import EncloseError

log = logging.getLogger(__name__)
MAX_CSV_RATE_HZ = 100.0
PERFORMANCE_PNG = "performance.png"
TRAJECTORY_PNG = "trajectory.png"


def write_run_outputs(
    run_dir: Path,
    series: RunSeries,
    info: RunInfo,
    extra: dict[str, Any] | None = None,
    marks_s: list[float] | None = None,
) -> Metrics:
    """Metrics from the full-rate series; CSV and figures from at most 100 Hz of it."""
    run_dir.mkdir(parents=True, exist_ok=True)
    angles = np.asarray(info.angles_rad)
    errors = error_series(series, info.successor, angles, info.rho_d_m)
    metrics = compute_metrics(series, errors, info.steady_from_s, info.eps_rho_m, info.eps_delta)
    faults = [{"label": label, "at_s": at_s, "end_s": end_s,
               **window_metrics(series, errors, (at_s, end_s), info.eps_rho_m, info.eps_delta)}
              for label, at_s, end_s in info.net_faults]
    write_metrics(run_dir, metrics, info,
                  {**(extra or {}), **({"net_faults": faults} if faults else {})})
    thin = series.decimate(_decimation(series.t_s))
    thin_errors = error_series(thin, info.successor, angles, info.rho_d_m)
    write_series(run_dir / SERIES_FILE, thin, thin_errors)
    _figures(run_dir, thin, info, marks_s or [])
    return metrics


def _decimation(t_s: np.ndarray) -> int:
    if len(t_s) < 2:
        return 1
    dt = float(np.median(np.diff(t_s)))
    return max(1, round(1.0 / (MAX_CSV_RATE_HZ * dt))) if dt > 0 else 1


def _figures(run_dir: Path, series: RunSeries, info: RunInfo, marks_s: list[float]) -> list[Path]:
    """`marks_s`: membership changes; with the launcher's events (launch.json) they are
    marks on every figure.  links.png only where links.csv exists (networked runs)."""
    angles = np.asarray(info.angles_rad)
    errors = error_series(series, info.successor, angles, info.rho_d_m)
    eps = (info.eps_rho_m, info.eps_delta)
    marks = run_marks(run_dir, marks_s, info.net_faults)
    performance_figure(series, errors, eps, run_dir / PERFORMANCE_PNG, marks)
    trajectory_figure(series, info.rho_d_m, run_dir / TRAJECTORY_PNG, marks)
    paths = [run_dir / PERFORMANCE_PNG, run_dir / TRAJECTORY_PNG]
    if (run_dir / LINKS_CSV).exists():
        link_health_figure(read_links_csv(run_dir / LINKS_CSV), run_dir / LINKS_PNG, marks)
        paths.append(run_dir / LINKS_PNG)
    return paths


def _marks(run_dir: Path) -> list[float]:
    """The membership changes recorded in metrics.json, if any."""
    try:
        metrics = json.loads((run_dir / METRICS_FILE).read_text())
        return [float(t) for t in metrics.get("membership", {}).get("changes_s", [])]
    except (OSError, ValueError, TypeError, AttributeError):
        return []


def regenerate_figures(run_dir: Path) -> list[Path]:
    """Figures again from a run directory's series.csv and run.json."""
    if not run_dir.is_dir():
        raise EncloseError(f"{run_dir} is not a run directory")
    info = read_info(run_dir)
    series = read_series(run_dir / SERIES_FILE, info.n, info.m)
    return _figures(run_dir, series, info, _marks(run_dir))


def register(sub: Any) -> None:
    parser = sub.add_parser("report", help="regenerate the figures of a run directory")
    parser.add_argument("run_dir", type=Path, help="directory written by simulate or run")
    parser.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    for path in regenerate_figures(args.run_dir):
        log.info("wrote %s", path)
    return 0
