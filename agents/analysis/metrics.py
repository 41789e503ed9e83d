"""Accuracy metrics of a run, computed the same way for lock-step and networked runs."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from agents.analysis.geometry import included_angles
from agents.analysis.timeseries import RunSeries

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
    tracker = SettleTracker()
    tracker.add(t_s, inside)
    return tracker.result()


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
    window = WindowAccumulator(window_s, eps_rho_m, eps_delta)
    window.add(series, errors)
    return window.result()


class WindowAccumulator:
    """`window_metrics` of a series fed in consecutive chunks (time order)."""

    def __init__(self, window_s: tuple[float, float], eps_rho_m: float,
                 eps_delta: float) -> None:
        self.start, self.end = window_s
        self.eps_rho_m, self.eps_delta = eps_rho_m, eps_delta
        self._worst: list[float | None] = [None, None, None]  # radius, angle, estimator
        self._closest: float | None = None
        self._after = SettleTracker()

    def add(self, series: RunSeries, errors: ErrorSeries) -> None:
        t = series.t_s
        during = (t >= self.start) & (t < self.end)
        if np.any(during):
            for k, values in enumerate((np.abs(errors.e_rho_m[during]),
                                        np.abs(errors.e_delta[during]),
                                        errors.estimator_error_m[during])):
                self._worst[k] = _fold_worst(self._worst[k], values.ravel())
            self._closest = _fold_least(self._closest,
                                        separation_series(series.follower_pos_m[during]))
        after = t >= self.end
        if np.any(after):
            inside = np.all((np.abs(errors.e_rho_m[after]) < self.eps_rho_m)
                            & (np.abs(errors.e_delta[after]) < self.eps_delta), axis=1)
            self._after.add(t[after], inside)

    def result(self) -> dict[str, float | None]:
        back = self._after.result()
        return {
            "radius_error_m": _or_nan(self._worst[0]),
            "angle_error": _or_nan(self._worst[1]),
            "estimator_error_m": _or_nan(self._worst[2]),
            "min_separation_m": _or_nan(self._closest),
            "recovery_s": None if back is None else max(0.0, back - self.end),
        }


class SettleTracker:
    """`settle_time` of (times, inside) fed in consecutive chunks."""

    def __init__(self) -> None:
        self._first: float | None = None
        self._settle: float | None = None  # the sample after the last one outside
        self._next = False  # the last one outside ended the previous chunk
        self._inside_last = False

    def add(self, t_s: FloatArray, inside: BoolArray) -> None:
        if not len(t_s):
            return
        if self._first is None:
            self._first = float(t_s[0])
        if self._next:
            self._settle, self._next = float(t_s[0]), False
        outside = np.nonzero(~inside)[0]
        if len(outside):
            after = outside[-1] + 1
            if after < len(t_s):
                self._settle = float(t_s[after])
            else:
                self._next = True
        self._inside_last = bool(inside[-1])

    def result(self) -> float | None:
        if self._first is None or not self._inside_last:
            return None
        return self._first if self._settle is None else self._settle


class _Maxima:
    """The largest errors and command jump over the rows a selection keeps."""

    def __init__(self) -> None:
        self.estimator: float | None = None  # NaN ignored, as `worst`
        self.radius = -math.inf  # NaN shows
        self.angle = -math.inf
        self.jump: float | None = None  # NaN ignored
        self.jumps = 0

    def add(self, errors: ErrorSeries, rows: BoolArray, jumps: FloatArray) -> None:
        if np.any(rows):
            self.estimator = _fold_worst(self.estimator, errors.estimator_error_m[rows])
            self.radius = _fold_max(self.radius, np.abs(errors.e_rho_m[rows]).max())
            self.angle = _fold_max(self.angle, np.abs(errors.e_delta[rows]).max())
        if jumps.size:
            self.jump = _fold_worst(self.jump, jumps)
            self.jumps += jumps.size


def _fold_worst(held: float | None, values: FloatArray) -> float | None:
    v = worst(values)
    if math.isnan(v):
        return held
    return v if held is None else max(held, v)


def _fold_least(held: float | None, values: FloatArray) -> float | None:
    v = least(values)
    if math.isnan(v):
        return held
    return v if held is None else min(held, v)


def _or_nan(v: float | None) -> float:
    return math.nan if v is None else v


def _fold_max(held: float, value: float) -> float:
    return math.nan if math.isnan(held) or math.isnan(value) else max(held, float(value))


class MetricsAccumulator:
    """`compute_metrics` of a series fed in consecutive chunks (time order): the same
    numbers, with memory for a chunk, not the run."""

    def __init__(self, steady_from_s: float, eps_rho_m: float, eps_delta: float) -> None:
        self.steady_from_s, self.eps_rho_m, self.eps_delta = steady_from_s, eps_rho_m, eps_delta
        self._steady, self._all = _Maxima(), _Maxima()
        self._last: tuple[FloatArray, bool] | None = None  # previous row's command, steady
        self._t_first: float | None = None
        self._t_last = math.nan
        self._samples = 0
        self._settle = SettleTracker()
        self._any_steady = False
        # The closest approach over the run, before steady_from_s and from it.
        self._closest: list[float | None] = [None, None, None]

    def add(self, series: RunSeries, errors: ErrorSeries) -> None:
        t = series.t_s
        if not len(t):
            return
        steady = t >= self.steady_from_s
        self._any_steady |= bool(steady.any())
        cmd = series.command_m_s
        if self._last is not None:
            cmd = np.concatenate([self._last[0][None], cmd])
            steady_pairs = np.concatenate([[self._last[1]], steady])
        else:
            steady_pairs = steady
        jumps = np.linalg.norm(np.diff(cmd, axis=0), axis=2)
        self._steady.add(errors, steady, jumps[steady_pairs[1:] & steady_pairs[:-1]])
        self._all.add(errors, np.ones_like(steady), jumps)
        self._last = (series.command_m_s[-1], bool(steady[-1]))
        self._settle.add(t, np.all((np.abs(errors.e_rho_m) < self.eps_rho_m)
                                   & (np.abs(errors.e_delta) < self.eps_delta), axis=1))
        separation = separation_series(series.follower_pos_m)
        for k, rows in enumerate((np.ones_like(steady), ~steady, steady)):
            self._closest[k] = _fold_least(self._closest[k], separation[rows])
        if self._t_first is None:
            self._t_first = float(t[0])
        self._t_last = float(t[-1])
        self._samples += len(t)

    def result(self) -> Metrics:
        """Over the steady rows, or over all of them if none is steady."""
        sel = self._steady if self._any_steady else self._all
        return Metrics(
            steady_from_s=float(self.steady_from_s),
            estimator_error_m=math.nan if sel.estimator is None else sel.estimator,
            # From true positions only: never NaN by design, so a NaN there must show.
            radius_error_m=sel.radius,
            angle_error=sel.angle,
            settle_time_s=self._settle.result(),
            command_jump_m_s=(math.nan if sel.jump is None else sel.jump) if sel.jumps else 0.0,
            duration_s=self._t_last - (math.nan if self._t_first is None else self._t_first),
            samples=self._samples,
            min_separation_m=_or_nan(self._closest[0]),
            min_separation_transient_m=_or_nan(self._closest[1]),
            min_separation_steady_m=_or_nan(self._closest[2]),
        )


def compute_metrics(
    series: RunSeries,
    errors: ErrorSeries,
    steady_from_s: float,
    eps_rho_m: float,
    eps_delta: float,
) -> Metrics:
    acc = MetricsAccumulator(steady_from_s, eps_rho_m, eps_delta)
    acc.add(series, errors)
    return acc.result()
