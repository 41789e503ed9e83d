"""A lying follower's run, in figures (issue 51): what the honest followers suffered during
the lie and after it, and when the liar's neighbours first refused it.

From a run directory's series.csv (the honest followers only: the liar's own published
estimate is a lie by construction) and launch.json (the followers' counters,
agents.follower.plausible).  Used by bench/bench_lie.py and tests/integration/test_liar_run.py.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

from deploy.report.verdict import read_verdict

BOUNDS = {"est": 0.0999, "e_rho": 0.0999, "e_delta": 0.0199}


def _rows(run_dir: Path) -> list[dict[str, float]]:
    with (run_dir / "series.csv").open() as f:
        return [{k: float(v) for k, v in row.items() if v not in ("", None)}
                for row in csv.DictReader(f)]


def _worst(row: dict[str, float], honest: list[int]) -> dict[str, float]:
    return {"est": max(abs(row.get(f"est{i}_est_err_m", math.inf)) for i in honest),
            "e_rho": max(abs(row.get(f"e{i}_e_rho_m", math.inf)) for i in honest),
            "e_delta": max(abs(row.get(f"e{i}_e_delta", math.inf)) for i in honest)}


def _separation(row: dict[str, float], n: int) -> float:
    pos = [(row[f"f{i}_x_m"], row[f"f{i}_y_m"]) for i in range(1, n + 1)]
    return min(math.dist(a, b) for k, a in enumerate(pos) for b in pos[k + 1:])


def lie_figures(run_dir: Path, at_s: float, lie_s: float, liar: int) -> dict[str, Any]:
    """The figures of one run (module docstring); `liar` 1-based."""
    rows = _rows(run_dir)
    n = sum(1 for k in rows[0] if k.startswith("est"))
    honest = [i for i in range(1, n + 1) if i != liar]
    end = at_s + lie_s
    during = [_worst(r, honest) for r in rows if at_s <= r["t_s"] < end]
    after = [(r["t_s"], _worst(r, honest)) for r in rows if r["t_s"] >= end]
    outside = [t for t, w in after if any(w[k] >= BOUNDS[k] for k in BOUNDS)]
    back_s = (max(outside) - end if outside else 0.0) if after else None
    late = [w for t, w in after if t >= end + 10.0]
    launch = json.loads((run_dir / "launch.json").read_text())
    status = launch.get("status_at_stop") or launch.get("status") or {}
    key = f"implausible_first_ms_f{liar - 1}"
    detected = {name: c[key] / 1000.0 for name, c in status.items() if key in c}
    liars = read_verdict(run_dir, "bench").liars
    return {
        "run": str(run_dir),
        "during_est_max_m": max((w["est"] for w in during), default=None),
        "during_e_rho_max_m": max((w["e_rho"] for w in during), default=None),
        "back_inside_after_s": back_s,
        "after10_est_max_m": max((w["est"] for w in late), default=None),
        "after10_e_rho_max_m": max((w["e_rho"] for w in late), default=None),
        "after10_e_delta_max": max((w["e_delta"] for w in late), default=None),
        "min_separation_m": min(_separation(r, n) for r in rows),
        "detected_s": detected,
        "detection_delay_s": (min(detected.values()) - at_s) if detected else None,
        "rejected": {name: c.get(f"implausible_f{liar - 1}", 0) for name, c in status.items()
                     if name.startswith("follower-")},
        "verdict_liars": list(liars),
        "verdict_names_liar": any(line.startswith(f"follower-{liar - 1} ") and " lied:" in line
                                  for line in liars),
    }
