"""Live progress of a networked run, for the launcher: `RUN_DIR/progress.json`.

Errors are those of `agents.analysis.metrics.error_series` -- the same definitions as the final
metrics -- over the last second of truth with each follower's latest state aligned.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from agents.analysis.metrics import error_series, worst
from deploy.recording.assembler import RunAssembler
from deploy.report.rundir import RunInfo

WINDOW_S = 1.0


def _worst_or_none(values: np.ndarray) -> float | None:
    """The largest value (NaN ignored, as in the final metrics: a silent follower's NaN
    columns do not hide the others); None when not finite."""
    v = worst(values)
    return v if math.isfinite(v) else None


def live_errors(asm: RunAssembler, info: RunInfo, window_s: float = WINDOW_S) -> dict[str, Any]:
    """Max |e_rho|, |e_delta| and estimator error over the last `window_s` of truth."""
    series = asm.recent_series(window_s)
    if series is None:
        return {"max_abs_e_rho_m": None, "max_abs_e_delta": None, "max_estimator_error_m": None}
    errors = error_series(series, info.successor, np.asarray(info.angles_rad), info.rho_d_m)
    return {
        "max_abs_e_rho_m": _worst_or_none(np.abs(errors.e_rho_m)),
        "max_abs_e_delta": _worst_or_none(np.abs(errors.e_delta)),
        "max_estimator_error_m": _worst_or_none(errors.estimator_error_m),
    }


def behind_s(now_s: float, newest_stamp_s: float) -> float | None:
    """progress.json "recorder_behind_s": the bus clock minus the newest sender stamp the
    recorder has processed -- its backlog.  Receive stamps cannot show it: a sample is
    stamped when it is drained, however long it waited.  None before any message."""
    return round(now_s - newest_stamp_s, 2) if math.isfinite(newest_stamp_s) else None


def write_json_atomic(path: Path, payload: dict[str, Any]) -> None:
    """Readers never see a half-written file: write a sibling, then rename over."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(payload, indent=2) + "\n")
    os.replace(tmp, path)
