"""A run directory: metrics.json, run.json (what the metrics were judged against), series.csv."""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.analysis.metrics import ErrorSeries, Metrics
from agents.analysis.timeseries import FloatArray, RunSeries, decimated_rows
from agents.scenario.model import Scenario
from deploy.report.weather_report import weather_text
from enclose_release import VERSION
from errors import EncloseError

SERIES_FILE = "series.csv"
SERIES_PARQUET = "series.parquet"
METRICS_FILE = "metrics.json"
RUN_FILE = "run.json"


@dataclass(frozen=True)
class RunInfo:
    """What a run directory needs to recompute errors and figures without the scenario file."""

    name: str
    kind: str
    n: int
    m: int
    successor: tuple[int, ...]
    angles_rad: tuple[float, ...]
    rho_d_m: float
    eps_rho_m: float
    eps_delta: float
    steady_from_s: float
    law: str = "paper"  # the followers' law: a shipped name or a module reference
    safety_distance_m: float = 1.0
    # The network faults: (label, at_s, end_s) in experiment time (transport.network_schema)
    net_faults: tuple[tuple[str, float, float], ...] = ()
    weather: str = ""  # the wind, GPS noise and sensor (deploy.report.weather_report); "": none
    wind_m_s: tuple[float, float] | None = None  # the mean wind, for the live view's arrow

    @staticmethod
    def from_scenario(scenario: Scenario, kind: str, duration_s: float) -> RunInfo:
        steady = scenario.run.steady_from_s
        return RunInfo(
            name=scenario.name,
            kind=kind,
            n=scenario.n,
            m=scenario.m,
            successor=scenario.successor,
            angles_rad=scenario.pattern.angles_rad,
            rho_d_m=scenario.pattern.rho_d_m,
            eps_rho_m=scenario.run.eps_rho_m,
            eps_delta=scenario.run.eps_delta,
            steady_from_s=duration_s / 2.0 if steady is None else steady,
            law=scenario.law.ref,
            safety_distance_m=scenario.run.safety_distance_m,
            net_faults=tuple((f.label(), f.at_s, f.end_s) for f in scenario.network.faults),
            weather=weather_text(scenario),
            wind_m_s=None if scenario.wind is None else scenario.wind.mean_m_s,
        )


def series_columns(n: int, m: int) -> list[str]:
    cols = ["t_s"]
    for prefix, count, unit in (("f", n, "m"), ("r", n, "m"), ("u", n, "m_s"), ("tgt", m, "m")):
        for i in range(count):
            cols += [f"{prefix}{i + 1}_x_{unit}", f"{prefix}{i + 1}_y_{unit}"]
    for name in ("z_m", "delta", "est_err_m", "e_rho_m", "e_delta"):
        cols += [f"{name.split('_')[0]}{i + 1}_{name}" for i in range(n)]
    return cols


def series_rows(series: RunSeries, errors: ErrorSeries) -> FloatArray:
    """The rows of series.csv (columns `series_columns`) as one (k, columns) array."""
    k = len(series.t_s)
    blocks = [series.t_s[:, None]]
    for arr in (series.follower_pos_m, series.estimate_m, series.command_m_s, series.target_pos_m):
        blocks.append(arr.reshape(k, -1))
    for err in (errors.z_m, errors.delta, errors.estimator_error_m, errors.e_rho_m, errors.e_delta):
        blocks.append(err)
    return np.hstack(blocks)


class SeriesWriter:
    """series.csv and series.parquet (the same rows, full precision in Parquet: what long
    runs are read back from), written chunk by chunk."""

    def __init__(self, run_dir: Path, n: int, m: int) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        self.columns = series_columns(n, m)
        self._csv = open(run_dir / SERIES_FILE, "w")  # noqa: SIM115  # closed in close()
        self._csv.write(",".join(self.columns) + "\n")
        self._schema = pa.schema([(c, pa.float64()) for c in self.columns])
        self._parquet = pq.ParquetWriter(run_dir / SERIES_PARQUET, self._schema)

    def add(self, series: RunSeries, errors: ErrorSeries) -> None:
        import pyarrow as pa

        rows = series_rows(series, errors)
        if not len(rows):
            return
        np.savetxt(self._csv, rows, delimiter=",", fmt="%.9g")
        self._parquet.write_table(pa.Table.from_arrays(
            [pa.array(rows[:, k]) for k in range(rows.shape[1])], schema=self._schema))

    def close(self) -> None:
        self._csv.close()
        self._parquet.close()

    def __enter__(self) -> SeriesWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def series_file(run_dir: Path) -> Path:
    """The file a run directory's series is read from: Parquet where there is one."""
    parquet = run_dir / SERIES_PARQUET
    return parquet if parquet.exists() else run_dir / SERIES_FILE


def read_series(path: Path, n: int, m: int, max_rows: int | None = None) -> RunSeries:
    """series.csv or series.parquet (by its suffix) as a RunSeries; with `max_rows`, every
    k-th row (and the last) such that at most about that many are kept."""
    width = 1 + 6 * n + 2 * m  # the series' columns; the errors after them are recomputed
    try:
        reader = _parquet_batches if path.suffix == ".parquet" else _csv_batches
        total, batches = reader(path, series_columns(n, m), width)
        every = 1 if max_rows is None else max(1, math.ceil(total / max_rows))
        kept, offset = [np.empty((0, width))], 0
        for data in batches:
            kept.append(data[decimated_rows(offset, len(data), every, total)])
            offset += len(data)
    except (OSError, ValueError) as exc:
        raise EncloseError(f"cannot read {path}: {exc}") from exc
    data = np.concatenate(kept)
    k, col = data.shape[0], 1
    arrays = []
    for count in (n, n, n, m):
        arrays.append(data[:, col : col + 2 * count].reshape(k, count, 2))
        col += 2 * count
    return RunSeries(data[:, 0], *arrays)


_READ_VALUES = 1 << 21  # per batch read from a CSV: 16 MB


def _parquet_batches(path: Path, names: list[str],
                     width: int) -> tuple[int, Iterator[FloatArray]]:
    """A row group at a time (the writer's chunks), without threads: reading ahead holds
    several at once."""
    import pyarrow.parquet as pq

    source = pq.ParquetFile(path)
    if source.schema_arrow.names != names:
        raise ValueError(f"its columns are not those of this run ({len(names)})")
    wanted = names[:width]

    def read() -> Iterator[FloatArray]:
        for g in range(source.num_row_groups):
            table = source.read_row_group(g, columns=wanted, use_threads=False)
            yield np.column_stack([c.to_numpy() for c in table.columns])

    return source.metadata.num_rows, read()


def _csv_batches(path: Path, names: list[str],
                 width: int) -> tuple[int, Iterator[FloatArray]]:
    with open(path) as f:
        total = sum(1 for _ in f) - 1
    rows = max(256, _READ_VALUES // len(names))

    def read() -> Iterator[FloatArray]:
        with open(path) as f:
            f.readline()
            while lines := list(itertools.islice(f, rows)):
                data = np.loadtxt(lines, delimiter=",", ndmin=2)
                if data.shape[1] != len(names):
                    raise EncloseError(f"{path}: expected {len(names)} columns, found "
                                       f"{data.shape[1]}")
                yield data[:, :width]

    return max(0, total), read()


def write_metrics(run_dir: Path, metrics: Metrics, info: RunInfo, extra: dict[str, Any]) -> None:
    payload = {**metrics.as_dict(), **extra, "enclose_version": VERSION}
    clean = {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v)
        for k, v in payload.items()
    }
    (run_dir / METRICS_FILE).write_text(json.dumps(clean, indent=2) + "\n")
    # Without weather run.json is what it was before the weather existed.
    fields = {k: v for k, v in info.__dict__.items()
              if k not in ("weather", "wind_m_s") or v}
    (run_dir / RUN_FILE).write_text(json.dumps(fields, indent=2) + "\n")


def read_info(run_dir: Path) -> RunInfo:
    path = run_dir / RUN_FILE
    try:
        raw = json.loads(path.read_text())
        raw["successor"] = tuple(raw["successor"])
        raw["angles_rad"] = tuple(raw["angles_rad"])
        raw["net_faults"] = tuple((str(a), float(b), float(c))
                                  for a, b, c in raw.get("net_faults", ()))
        if raw.get("wind_m_s") is not None:
            x, y = raw["wind_m_s"]
            raw["wind_m_s"] = (float(x), float(y))
        return RunInfo(**raw)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise EncloseError(f"{path} is missing or malformed: {exc}") from exc
