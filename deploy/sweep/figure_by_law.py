"""A sweep's laws side by side: `error_vs_law.png`, the three errors of each law of the
`law` axis as bars (mean over the seeds, min-max whiskers) against the paper's bounds."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: runs on headless machines and in CI
import matplotlib.pyplot as plt
import numpy as np

from deploy.sweep.figures import (
    PLAIN,
    SPARSE,
    STYLE,
    bound_of,
    held_text,
    mean_and_bars,
    point_of,
    point_text,
    points,
)
from deploy.sweep.spec import SweepSpec
from deploy.sweep.table import Row

log = logging.getLogger("enclose.sweep")
NAME = "error_vs_law.png"
METRICS = ("estimator_error_m", "radius_error_m", "angle_error")


def law_figures(spec: SweepSpec, rows: Sequence[Row]) -> list[Path]:
    """`error_vs_law.png` when the law is a grid axis with more than one value."""
    if "law" not in spec.varying() or not rows:
        log.info("%s skipped: law is not a grid axis with more than one value", NAME)
        return []
    path = spec.out / NAME
    error_by_law(spec, rows, path)
    return [path]


def error_by_law(spec: SweepSpec, rows: Sequence[Row], path: Path) -> list[np.ndarray]:
    """One panel per error, a bar per law; the other axes held at their first value.  The
    means drawn, one array per panel."""
    lkeys, laws = spec.partners("law"), points(spec, "law")
    held = [(keys, pts[0]) for keys, pts in spec.grid if keys != lkeys]
    kept = [r for r in rows if all(point_of(r, keys) == first for keys, first in held)]
    cells = [[r for r in kept if point_of(r, lkeys) == pt] for pt in laws]
    x = np.arange(len(laws))
    fig, axs = plt.subplots(1, len(METRICS), figsize=(4.2 * len(METRICS), 4.6))
    drawn = []
    for ax, metric in zip(axs, METRICS, strict=True):
        means, bars = mean_and_bars(cells, metric)
        drawn.append(means)
        ax.bar(x, means, yerr=bars, capsize=5, color=[f"C{k}" for k in range(len(laws))])
        for k, v in enumerate(means):
            if np.isfinite(v):
                ax.annotate(f"{v:.3g}", (x[k], v), ha="center", va="bottom", fontsize=9,
                            xytext=(0, 3), textcoords="offset points")
        bound = bound_of(spec, metric)
        if bound is not None:
            ax.axhline(bound, color="k", ls="--", lw=1, label=f"paper's bound {bound:g}")
            ax.legend(fontsize=8)
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(PLAIN)
        ax.yaxis.set_minor_formatter(SPARSE)
        ax.set_xticks(x, [point_text(pt) for pt in laws], rotation=10)
        ax.set_ylabel(STYLE[metric][0])
        ax.set_title(metric)
        ax.grid(alpha=0.3, which="both", axis="y")
    held_at = ", ".join(f"{'/'.join(k)}={point_text(p)}" for k, p in held)
    fig.suptitle(f"errors by law; mean over {spec.repeats} seed(s), whiskers: min-max; "
                 f"other axes at their first value: {held_at or 'none'}\n{held_text(spec)}",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return drawn
