"""How a run recovered after disturbances: time back inside the paper's bounds, worst error.

Reads a run directory's `series.csv` (the errors every metric uses) and, for each
disturbance window [resume, next disturbance or end), reports how long after the
resume every follower's estimator, radius and angle errors are back inside the
paper's bounds for good (to the end of the window), and the worst errors after the
resume.  Pure apart from reading the file; the pausing itself is the caller's.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from deploy.report.rundir import SERIES_FILE

EPS_M = 0.0999  # the paper's bounds (docs/index.md: settle_time_s)
EPS_DELTA = 0.0199
FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Errors:
    t_s: FloatArray  # (k,)
    estimator_m: FloatArray  # (k,) worst follower at each sample
    radius_m: FloatArray
    angle: FloatArray

    @staticmethod
    def read(run_dir: Path) -> Errors:
        path = run_dir / SERIES_FILE
        names = path.read_text().split("\n", 1)[0].split(",")
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)

        def worst(suffix: str) -> FloatArray:
            cols = [k for k, name in enumerate(names) if name.endswith(suffix)]
            return np.asarray(np.abs(data[:, cols]).max(axis=1))

        return Errors(data[:, 0], worst("_est_err_m"), worst("_e_rho_m"), worst("_e_delta"))

    def inside(self) -> NDArray[np.bool_]:
        return (self.estimator_m < EPS_M) & (self.radius_m < EPS_M) & (self.angle < EPS_DELTA)


@dataclass(frozen=True)
class Recovery:
    resume_s: float  # experiment time of the resume
    window_end_s: float
    recovered_after_s: float | None  # None: not back inside the bounds for good in the window
    worst_estimator_m: float
    worst_radius_m: float
    worst_angle: float

    def as_dict(self) -> dict[str, float | None]:
        return asdict(self)


def recovery(errors: Errors, resume_s: float, end_s: float) -> Recovery:
    """Recovery after `resume_s`, judged on the samples in [resume_s, end_s)."""
    sel = (errors.t_s >= resume_s) & (errors.t_s < end_s)
    t, ok = errors.t_s[sel], errors.inside()[sel]
    if not t.size:
        return Recovery(resume_s, end_s, None, np.nan, np.nan, np.nan)
    bad = np.nonzero(~ok)[0]
    if not bad.size:
        after: float | None = 0.0
    elif bad[-1] + 1 < t.size:
        after = float(t[bad[-1] + 1] - resume_s)
    else:
        after = None
    return Recovery(resume_s, end_s, after, float(errors.estimator_m[sel].max()),
                    float(errors.radius_m[sel].max()), float(errors.angle[sel].max()))


def recoveries(run_dir: Path, pauses_wall_s: list[tuple[float, float]]) -> list[Recovery]:
    """One Recovery per (stop, resume) pair of wall-clock times (time.time()), each judged
    from its resume to the next stop or the end of the run."""
    start = json.loads((run_dir / "metrics.json").read_text())["start_stamp_s"]
    errors = Errors.read(run_dir)
    pauses = sorted((a - start, b - start) for a, b in pauses_wall_s)
    ends = [stop for stop, _ in pauses[1:]] + [float(errors.t_s[-1]) + 1.0]
    return [recovery(errors, resume, end) for (_, resume), end in zip(pauses, ends, strict=True)]
