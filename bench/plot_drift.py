"""|mean(r_i) - LAP| over time for several run directories: the estimators' drift, side by side.

Run: python bench/plot_drift.py OUT.png LABEL=RUN_DIR [LABEL=RUN_DIR ...]
The mean of the estimates equals the LAP exactly for the paper's estimator on an ideal
network; what a run shows above zero is drift (plus the estimates still in flight).
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from deploy.report.rundir import SERIES_FILE, read_info, read_series


def drift(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    info = read_info(run_dir)
    series = read_series(run_dir / SERIES_FILE, info.n, info.m)
    return series.t_s, np.linalg.norm(series.estimate_m.mean(axis=1) - series.lap_m, axis=1)


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__)
        return 2
    fig, ax = plt.subplots(figsize=(10, 4.5))
    for item in argv[1:]:
        label, _, path = item.partition("=")
        t, d = drift(Path(path))
        ax.plot(t, d, lw=1.0, label=f"{label} (end {d[-1]:.3f} m)")
        print(f"{label}: |mean(r) - LAP| max {d.max():.4f} m, at the end {d[-1]:.4f} m")
    ax.axhline(0.0999, color="k", ls="--", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("|mean(r_i) - LAP| [m]")
    ax.set_title("drift of the estimates' mean (dashed: the paper's bound)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(argv[0], dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
