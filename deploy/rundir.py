"""A run directory: metrics.json, run.json (what the metrics were judged against), series.csv."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.core.metrics import ErrorSeries, Metrics
from agents.core.timeseries import RunSeries
from agents.scenario.model import Scenario
from deploy.version import enclose_version
from transport.errors import EncloseError

SERIES_FILE = "series.csv"
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
        )


def series_columns(n: int, m: int) -> list[str]:
    cols = ["t_s"]
    for prefix, count, unit in (("f", n, "m"), ("r", n, "m"), ("u", n, "m_s"), ("tgt", m, "m")):
        for i in range(count):
            cols += [f"{prefix}{i + 1}_x_{unit}", f"{prefix}{i + 1}_y_{unit}"]
    for name in ("z_m", "delta", "est_err_m", "e_rho_m", "e_delta"):
        cols += [f"{name.split('_')[0]}{i + 1}_{name}" for i in range(n)]
    return cols


def write_series(path: Path, series: RunSeries, errors: ErrorSeries) -> None:
    k = len(series.t_s)
    blocks = [series.t_s[:, None]]
    for arr in (series.follower_pos_m, series.estimate_m, series.command_m_s, series.target_pos_m):
        blocks.append(arr.reshape(k, -1))
    for err in (errors.z_m, errors.delta, errors.estimator_error_m, errors.e_rho_m, errors.e_delta):
        blocks.append(err)
    n, m = series.follower_pos_m.shape[1], series.target_pos_m.shape[1]
    header = ",".join(series_columns(n, m))
    np.savetxt(path, np.hstack(blocks), delimiter=",", header=header, comments="", fmt="%.9g")


def read_series(path: Path, n: int, m: int) -> RunSeries:
    try:
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, ValueError) as exc:
        raise EncloseError(f"cannot read {path}: {exc}") from exc
    if data.shape[1] != len(series_columns(n, m)):
        raise EncloseError(
            f"{path}: expected {len(series_columns(n, m))} columns, found {data.shape[1]}"
        )
    k, col = data.shape[0], 1
    arrays = []
    for count in (n, n, n, m):
        arrays.append(data[:, col : col + 2 * count].reshape(k, count, 2))
        col += 2 * count
    return RunSeries(data[:, 0], *arrays)


def write_metrics(run_dir: Path, metrics: Metrics, info: RunInfo, extra: dict[str, Any]) -> None:
    payload = {**metrics.as_dict(), **extra, "enclose_version": enclose_version()}
    clean = {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v)
        for k, v in payload.items()
    }
    (run_dir / METRICS_FILE).write_text(json.dumps(clean, indent=2) + "\n")
    (run_dir / RUN_FILE).write_text(json.dumps(info.__dict__, indent=2) + "\n")


def read_info(run_dir: Path) -> RunInfo:
    path = run_dir / RUN_FILE
    try:
        raw = json.loads(path.read_text())
        raw["successor"] = tuple(raw["successor"])
        raw["angles_rad"] = tuple(raw["angles_rad"])
        raw["net_faults"] = tuple((str(a), float(b), float(c))
                                  for a, b, c in raw.get("net_faults", ()))
        return RunInfo(**raw)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise EncloseError(f"{path} is missing or malformed: {exc}") from exc
