"""Accuracy metrics of a run, computed the same way for lock-step and networked runs."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from agents.core.geometry import included_angles
from agents.core.timeseries import RunSeries

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class ErrorSeries:
    """Per-sample errors, (k, n) each: estimated (z, delta) and real (e_rho, e_delta)."""

    z_m: FloatArray
    delta: FloatArray
    estimator_error_m: FloatArray
    e_rho_m: FloatArray
    e_delta: FloatArray


@dataclass(frozen=True)
class Metrics:
    steady_from_s: float
    estimator_error_m: float
    radius_error_m: float
    angle_error: float
    settle_time_s: float | None
    command_jump_m_s: float
    duration_s: float
    samples: int
    # The closest approach of any two vehicles, over the run and in each phase (before
    # and from steady_from_s): a law inside its bounds may still bring two together.
    min_separation_m: float
    min_separation_transient_m: float
    min_separation_steady_m: float

    def as_dict(self) -> dict[str, float | int | None]:
        return asdict(self)


def error_series(
    series: RunSeries, successor: tuple[int, ...], angles_rad: FloatArray, rho_d_m: float
) -> ErrorSeries:
    succ = np.asarray(successor)
    pos, est = series.follower_pos_m, series.estimate_m
    lap = series.lap_m[:, None, :]
    succ_pos = pos[:, succ, :]
    rho_est = np.linalg.norm(pos - est, axis=2)
    rho_true = np.linalg.norm(pos - lap, axis=2)
    return ErrorSeries(
        z_m=rho_est - rho_d_m,
        delta=included_angles(pos, succ_pos, est) / angles_rad - 1.0,
        estimator_error_m=np.linalg.norm(est - lap, axis=2),
        e_rho_m=rho_true - rho_d_m,
        e_delta=included_angles(pos, succ_pos, lap) / angles_rad - 1.0,
    )


def settle_time(t_s: FloatArray, inside: BoolArray) -> float | None:
    """First time after which `inside` (k,) holds to the end; None if it fails at the end."""
    if len(inside) == 0 or not inside[-1]:
        return None
    outside = np.nonzero(~inside)[0]
    return float(t_s[0]) if len(outside) == 0 else float(t_s[outside[-1] + 1])


def worst(values: FloatArray) -> float:
    """The largest value, NaN ignored: a networked follower that sent no state has NaN
    estimates and commands (deploy.recording.assembler), and the others still count.
    NaN only when every value is NaN."""
    finite = values[~np.isnan(values)]
    return float(finite.max()) if finite.size else float("nan")


def separation_series(pos_m: FloatArray) -> FloatArray:
    """Per sample (k,), the smallest distance between two of the (k, n, 2) positions.
    One vehicle at a time against the later ones: (k, n) at most in memory, not (k, n, n).
    NaN positions are ignored; NaN where no pair is known."""
    k, n = pos_m.shape[0], pos_m.shape[1]
    closest = np.full(k, np.inf)
    for i in range(n - 1):
        d = np.linalg.norm(pos_m[:, i + 1:, :] - pos_m[:, i:i + 1, :], axis=2)
        closest = np.minimum(closest, np.where(np.isnan(d), np.inf, d).min(axis=1))
    return np.where(np.isinf(closest), np.nan, closest)


def least(values: FloatArray) -> float:
    """The smallest value, NaN ignored (NaN when none is known)."""
    finite = values[~np.isnan(values)]
    return float(finite.min()) if finite.size else float("nan")


def window_metrics(
    series: RunSeries, errors: ErrorSeries, window_s: tuple[float, float],
    eps_rho_m: float, eps_delta: float,
) -> dict[str, float | None]:
    """A network fault's window [start, end): the worst true errors and the closest
    approach during it, and its recovery time: from its end until the errors are back
    inside the bounds for the rest of the run (None: never; 0: they never left)."""
    start, end = window_s
    during = (series.t_s >= start) & (series.t_s < end)
    after = series.t_s >= end
    inside = np.all((np.abs(errors.e_rho_m) < eps_rho_m) & (np.abs(errors.e_delta) < eps_delta),
                    axis=1)
    back = settle_time(series.t_s[after], inside[after])
    return {
        "radius_error_m": worst(np.abs(errors.e_rho_m[during]).ravel()),
        "angle_error": worst(np.abs(errors.e_delta[during]).ravel()),
        "estimator_error_m": worst(errors.estimator_error_m[during].ravel()),
        "min_separation_m": least(separation_series(series.follower_pos_m[during])),
        "recovery_s": None if back is None else max(0.0, back - end),
    }


def compute_metrics(
    series: RunSeries,
    errors: ErrorSeries,
    steady_from_s: float,
    eps_rho_m: float,
    eps_delta: float,
) -> Metrics:
    steady = series.t_s >= steady_from_s
    if not np.any(steady):
        steady = np.ones_like(series.t_s, dtype=bool)
    inside = np.all(
        (np.abs(errors.e_rho_m) < eps_rho_m) & (np.abs(errors.e_delta) < eps_delta), axis=1
    )
    jumps = np.linalg.norm(np.diff(series.command_m_s, axis=0), axis=2)
    steady_jumps = jumps[steady[1:] & steady[:-1]]
    separation = separation_series(series.follower_pos_m)
    return Metrics(
        steady_from_s=float(steady_from_s),
        estimator_error_m=worst(errors.estimator_error_m[steady]),
        # From true positions only: never NaN by design, so a NaN there must show.
        radius_error_m=float(np.abs(errors.e_rho_m[steady]).max()),
        angle_error=float(np.abs(errors.e_delta[steady]).max()),
        settle_time_s=settle_time(series.t_s, inside),
        command_jump_m_s=worst(steady_jumps) if steady_jumps.size else 0.0,
        duration_s=float(series.t_s[-1] - series.t_s[0]),
        samples=len(series.t_s),
        min_separation_m=least(separation),
        min_separation_transient_m=least(separation[series.t_s < steady_from_s]),
        min_separation_steady_m=least(separation[series.t_s >= steady_from_s]),
    )
