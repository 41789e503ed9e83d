"""Turn a run into metrics.json, series.csv/series.parquet and figures: one code path for all
runs, lock-step (a series in memory) or recorded (read from disk chunk by chunk)."""

from __future__ import annotations

import argparse
import json
import logging
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import fields
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from agents.analysis.metrics import Metrics, MetricsAccumulator, WindowAccumulator, error_series
from agents.analysis.timeseries import FloatArray, RunSeries, decimated_rows
from deploy.report.link_history import LINKS_CSV, read_links_csv
from deploy.report.rundir import (
    METRICS_FILE,
    RunInfo,
    SeriesWriter,
    read_info,
    read_series,
    series_file,
    write_metrics,
)
from errors import EncloseError

log = logging.getLogger(__name__)
MAX_CSV_RATE_HZ = 100.0
# Samples drawn per figure at most: 240 s of the CSV's 100 Hz, and 400 000 follower-samples
# (ring64: 6 250); a longer run's figures take every k-th sample (marks are drawn at their
# own times).  Drawing costs memory per point: a 20-minute ring64 run read whole went
# to ~700 MB.
FIGURE_ROWS = 24_000
FIGURE_VALUES = 400_000
PERFORMANCE_PNG = "performance.png"
TRAJECTORY_PNG = "trajectory.png"


class SeriesSource(Protocol):
    """A run's series read in consecutive chunks (time order), its time column known first."""

    t_s: FloatArray

    def chunks(self) -> Iterator[RunSeries]: ...


class ChunkSink(Protocol):
    """Something more to compute from each chunk (e.g. the membership phases)."""

    def add(self, series: RunSeries) -> None: ...


class WholeSeries:
    """A series in memory as a one-chunk source (lock-step runs)."""

    def __init__(self, series: RunSeries) -> None:
        self.t_s = series.t_s
        self._series = series

    def chunks(self) -> Iterator[RunSeries]:
        yield self._series


def write_run_outputs(
    run_dir: Path,
    series: RunSeries | SeriesSource,
    info: RunInfo,
    extra: Mapping[str, Any] | Callable[[], Mapping[str, Any]] | None = None,
    marks_s: list[float] | None = None,
    sinks: Sequence[ChunkSink] = (),
    figures: bool = True,
) -> Metrics:
    """Metrics from the full-rate series; series.csv and series.parquet at most 100 Hz of
    it; figures from the rows of series.parquet that `enclose report` draws (taken on the
    way: reading a wide Parquet file back costs ~75 kB a column a row group).  One pass
    over the chunks; `extra` (metrics.json's other keys) may be a function, called once the
    pass (and `sinks`) are done.  `figures` False: none drawn (`enclose report` draws them
    from the series file later)."""
    source = WholeSeries(series) if isinstance(series, RunSeries) else series
    run_dir.mkdir(parents=True, exist_ok=True)
    angles = np.asarray(info.angles_rad)
    every, total, offset = _decimation(source.t_s), len(source.t_s), 0
    thin_total = len(decimated_rows(0, total, every, total))
    # The figures' rows, taken on the way; none kept when no figure is drawn.
    drawn = _Drawn(thin_total, figure_rows(info.n)) if figures else None
    metrics = MetricsAccumulator(info.steady_from_s, info.eps_rho_m, info.eps_delta)
    faults = [(label, at_s, end_s, WindowAccumulator((at_s, end_s), info.eps_rho_m,
                                                     info.eps_delta))
              for label, at_s, end_s in info.net_faults]
    with SeriesWriter(run_dir, info.n, info.m) as writer:
        for chunk in source.chunks():
            errors = error_series(chunk, info.successor, angles, info.rho_d_m)
            metrics.add(chunk, errors)
            for *_, window in faults:
                window.add(chunk, errors)
            for sink in sinks:
                sink.add(chunk)
            thin = chunk.take(decimated_rows(offset, len(chunk.t_s), every, total))
            writer.add(thin, error_series(thin, info.successor, angles, info.rho_d_m))
            if drawn is not None:
                drawn.add(thin)
            offset += len(chunk.t_s)
    result = metrics.result()
    windows = [{"label": label, "at_s": at_s, "end_s": end_s, **window.result()}
               for label, at_s, end_s, window in faults]
    write_metrics(run_dir, result, info, {**(extra() if callable(extra) else extra or {}),
                                          **({"net_faults": windows} if windows else {})})
    if drawn is not None:
        _figures(run_dir, info, marks_s or [], drawn.series())
    return result


def figure_rows(n: int) -> int:
    return min(FIGURE_ROWS, FIGURE_VALUES // max(1, n))


class _Drawn:
    """The rows of the series file that `read_series(..., figure_rows(n))` gives back."""

    def __init__(self, total: int, max_rows: int) -> None:
        self.total, self.every = total, max(1, math.ceil(total / max_rows))
        self.offset = 0
        self.parts: list[RunSeries] = []

    def add(self, thin: RunSeries) -> None:
        self.parts.append(thin.take(decimated_rows(self.offset, len(thin.t_s), self.every,
                                                   self.total)))
        self.offset += len(thin.t_s)

    def series(self) -> RunSeries:
        return RunSeries(*(np.concatenate([getattr(p, f.name) for p in self.parts])
                           for f in fields(RunSeries)))


def _decimation(t_s: np.ndarray) -> int:
    if len(t_s) < 2:
        return 1
    dt = float(np.median(np.diff(t_s)))
    return max(1, round(1.0 / (MAX_CSV_RATE_HZ * dt))) if dt > 0 else 1


def _figures(run_dir: Path, info: RunInfo, marks_s: list[float],
             series: RunSeries | None = None) -> list[Path]:
    """From the run's series (`figure_rows` samples of it at most, read from the run's
    series file unless given: a long run's figures stay readable, quick and small);
    `marks_s`: membership changes; with the launcher's events (launch.json) they are marks
    on every figure.  links.png only where links.csv exists (networked runs)."""
    # Imported to draw only: matplotlib costs ~0.6 s of CPU to import, which a run without
    # figures (--no-figures) need not pay.
    from deploy.report.link_figures import LINKS_PNG, link_health_figure
    from deploy.report.marks import run_marks
    from deploy.report.run_figures import performance_figure, trajectory_figure

    if series is None:
        series = read_series(series_file(run_dir), info.n, info.m, figure_rows(info.n))
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
    """Figures again from a run directory's series (series.parquet, or series.csv where a
    run has none) and run.json."""
    if not run_dir.is_dir():
        raise EncloseError(f"{run_dir} is not a run directory")
    return _figures(run_dir, read_info(run_dir), _marks(run_dir))


def register(sub: Any) -> None:
    parser = sub.add_parser("report", help="regenerate the figures of a run directory")
    parser.add_argument("run_dir", type=Path, help="directory written by simulate or run")
    parser.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    for path in regenerate_figures(args.run_dir):
        log.info("wrote %s", path)
    return 0
