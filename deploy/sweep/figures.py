"""Figures of a sweep: a heatmap per metric, and the errors against loss and against delay."""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only: runs on headless machines and in CI
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import LogNorm, Normalize
from matplotlib.ticker import FuncFormatter

from deploy.sweep.spec import SweepSpec
from deploy.sweep.table import DELIVERED, METRICS, RECOVERY, Row
from deploy.sweep.values import Value, format_value

log = logging.getLogger("enclose.sweep")
Point = tuple[Value, ...]
# metric -> (label, log colour scale, bound: "rho" | "delta" | None)
STYLE: dict[str, tuple[str, bool, str | None]] = {
    "estimator_error_m": ("|r - LAP| [m]", True, "rho"),
    "radius_error_m": ("|e_rho| [m]", True, "rho"),
    "angle_error": ("|e_delta|", True, "delta"),
    "settle_time_s": ("settle time [s]", False, None),
    "command_jump_m_s": ("command jump [m/s]", False, None),
    "min_separation_m": ("closest approach [m]", False, None),
    RECOVERY: ("recovery after the network fault [s]", False, None),
    DELIVERED: ("delivered ratio", False, None),
}
PLAIN = FuncFormatter(lambda v, _: f"{v:g}")  # 0.06, not 6 x 10^-2, on log axes
# minor ticks of a log axis: only 2 and 5 of each decade, so that labels do not collide
SPARSE = FuncFormatter(
    lambda v, _: f"{v:g}" if v > 0 and round(v / 10 ** math.floor(math.log10(v))) in (2, 5) else ""
)
LINES = (("loss", "error_vs_loss.png"), ("delay_ms", "error_vs_delay.png"))


def write_figures(spec: SweepSpec, rows: Sequence[Row]) -> list[Path]:
    """Figures from the finished cells (`rows`); what cannot be drawn is skipped with a log."""
    if not rows:
        log.info("no finished cell yet: no figures")
        return []
    paths: list[Path] = []
    axes = spec.heatmap or (spec.varying()[:2] if len(spec.varying()) >= 2 else None)
    if axes is None:
        log.info("heatmaps skipped: fewer than two grid axes with more than one value")
    else:
        for metric in (*METRICS, DELIVERED, RECOVERY):
            if any(r.state.metrics.get(metric) is not None for r in rows):
                paths.append(spec.out / f"heatmap_{metric}.png")
                heatmap(spec, rows, metric, (axes[0], axes[1]), paths[-1])
    for key, name in LINES:
        if key not in spec.varying():
            log.info("%s skipped: %s is not a grid axis with more than one value", name, key)
            continue
        paths.append(spec.out / name)
        error_against(spec, rows, key, paths[-1])
    return paths


def points(spec: SweepSpec, key: str) -> list[Point]:
    """The values of `key`'s axis (with the keys paired with it), in file order."""
    return next(list(pts) for keys, pts in spec.grid if key in keys)


def point_of(row: Row, keys: Sequence[str]) -> Point:
    values = dict(row.cell.values)
    return tuple(values[k] for k in keys)


def mean_of(rows: Sequence[Row], metric: str) -> float:
    """Mean over the repeats; NaN if there is none or one has no value (e.g. never settled)."""
    values = [r.state.metrics.get(metric) for r in rows]
    if not values or any(v is None for v in values):
        return math.nan
    return float(np.mean([float(v) for v in values if v is not None]))


def spread_of(rows: Sequence[Row], metric: str) -> tuple[float, float, float]:
    """(mean, min, max) over the repeats (seeds); NaNs as `mean_of`."""
    mean = mean_of(rows, metric)
    if not np.isfinite(mean):
        return math.nan, math.nan, math.nan
    values = [float(v) for v in (r.state.metrics.get(metric) for r in rows) if v is not None]
    return mean, min(values), max(values)


def mean_and_bars(cells: Sequence[Sequence[Row]], metric: str) -> tuple[np.ndarray, np.ndarray]:
    """Per point: the mean over its seeds, and error bars (2, points) down to the lowest and
    up to the highest seed."""
    stats = np.array([spread_of(rows, metric) for rows in cells]).reshape(len(cells), 3)
    return stats[:, 0], np.vstack([stats[:, 0] - stats[:, 1], stats[:, 2] - stats[:, 0]])


def point_text(pt: Point) -> str:
    return "/".join(format_value(v) for v in pt)


def bound_of(spec: SweepSpec, metric: str) -> float | None:
    kind = STYLE[metric][2]
    return spec.eps_rho_m if kind == "rho" else spec.eps_delta if kind == "delta" else None


@dataclass(frozen=True)
class Panels:
    """A metric on an (y, x) grid, one grid per combination of the other varying axes."""

    xkeys: tuple[str, ...]
    ykeys: tuple[str, ...]
    xs: list[Point]
    ys: list[Point]
    panel_keys: tuple[str, ...]
    panels: list[Point]
    grids: list[np.ndarray]  # mean over the repeats; NaN where none
    ran: list[np.ndarray]  # True where a finished cell exists
    spans: list[np.ndarray]  # max - min over the repeats (0 with one seed); NaN where none


def panel_grids(spec: SweepSpec, rows: Sequence[Row], metric: str, axes: tuple[str, str]) -> Panels:
    xkeys, ykeys = spec.partners(axes[0]), spec.partners(axes[1])
    xs, ys = points(spec, axes[0]), points(spec, axes[1])
    rest = [keys for keys, pts in spec.grid if keys not in (xkeys, ykeys) and len(pts) > 1]
    panel_keys = tuple(k for keys in rest for k in keys)
    panels = list(dict.fromkeys(point_of(r, panel_keys) for r in rows))
    grids, ran, spans = [], [], []
    for panel in panels:
        grid = np.full((len(ys), len(xs)), np.nan)
        span = np.full((len(ys), len(xs)), np.nan)
        present = np.zeros(grid.shape, dtype=bool)
        for (i, y), (j, x) in itertools.product(enumerate(ys), enumerate(xs)):
            match = [
                r for r in rows
                if point_of(r, panel_keys) == panel
                and point_of(r, xkeys) == x and point_of(r, ykeys) == y
            ]
            mean, lo, hi = spread_of(match, metric) if match else (np.nan,) * 3
            grid[i, j], span[i, j] = mean, hi - lo
            present[i, j] = bool(match)
        grids.append(grid)
        ran.append(present)
        spans.append(span)
    return Panels(xkeys, ykeys, xs, ys, panel_keys, panels, grids, ran, spans)


def colour_norm(grids: list[np.ndarray], log_scale: bool, bound: float | None) -> Normalize:
    finite = np.concatenate([g[np.isfinite(g)] for g in grids])
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    if log_scale and lo > 0:
        if bound is not None:  # the bound sits inside the colour range
            lo, hi = min(lo, bound / 2), max(hi, bound * 2)
        return LogNorm(lo, hi)
    return Normalize(lo, hi if hi > lo else lo + 1)


def heatmap(
    spec: SweepSpec, rows: Sequence[Row], metric: str, axes: tuple[str, str], path: Path
) -> None:
    p = panel_grids(spec, rows, metric, axes)
    xkeys, ykeys, xs, ys, panel_keys, panels = (
        p.xkeys, p.ykeys, p.xs, p.ys, p.panel_keys, p.panels)
    grids, ran = p.grids, p.ran
    label, log_scale, _ = STYLE[metric]
    bound = bound_of(spec, metric)
    norm = colour_norm(grids, log_scale, bound)
    use_log = isinstance(norm, LogNorm)
    ncols = min(len(panels), 3)
    nrows = math.ceil(len(panels) / ncols)
    cell_w = max(1.2, 0.9 + 0.35 * max(len(point_text(x)) for x in xs) / 2)
    fig, axs = plt.subplots(
        nrows, ncols, squeeze=False, layout="constrained",
        figsize=(ncols * (cell_w * len(xs) + 1.6) + 1.5, nrows * (0.6 * len(ys) + 1.6) + 1.0),
    )
    image = None
    missing = "never" if metric == "settle_time_s" else "none"
    for ax, panel, grid, present, span in zip(axs.flat, panels, grids, ran, p.spans,
                                              strict=False):
        image = ax.imshow(grid, norm=norm, cmap="viridis", origin="lower", aspect="auto")
        annotate(ax, grid, np.where(present, missing, "no run"), (norm, image.cmap), bound,
                 span if spec.repeats > 1 else None)
        ax.set_xticks(range(len(xs)), [point_text(x) for x in xs])
        ax.set_yticks(range(len(ys)), [point_text(y) for y in ys])
        ax.set_xlabel("/".join(xkeys))
        ax.set_ylabel("/".join(ykeys))
        ax.set_title(", ".join(f"{k}={format_value(v)}" for k, v in zip(panel_keys, panel,
                                                                       strict=True)), fontsize=9)
    for ax in axs.flat[len(panels):]:
        ax.set_visible(False)
    if image is not None:
        cbar = fig.colorbar(image, ax=axs, shrink=0.9)
        cbar.set_label(label)
        if use_log:
            cbar.ax.yaxis.set_major_formatter(PLAIN)
            cbar.ax.yaxis.set_minor_formatter(SPARSE)
        if bound is not None:
            cbar.ax.axhline(bound, color="r", lw=2)
    note = f"; bold red: above the paper's bound {bound:g} (red line)" if bound else ""
    spread = " (below it: max - min over the seeds)" if spec.repeats > 1 else ""
    fig.suptitle(f"{metric}: mean over {spec.repeats} seed(s){spread}{note}\n{held_text(spec)}",
                 fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def annotate(
    ax: Axes, grid: np.ndarray, blank: np.ndarray, colours: tuple[Normalize, Any],
    bound: float | None, span: np.ndarray | None = None,
) -> None:
    """Each value in its cell (bold red above the bound), with the spread over the seeds
    under it when given; `blank` says why a cell has none."""
    norm, cmap = colours
    for (i, j), v in np.ndenumerate(grid):
        if not np.isfinite(v):
            ax.text(j, i, str(blank[i, j]), ha="center", va="center", fontsize=9, color="0.3")
            continue
        over = bound is not None and v > bound
        r, g, b, _ = cmap(norm(v))
        ink = "k" if 0.299 * r + 0.587 * g + 0.114 * b > 0.5 else "w"
        spread = "" if span is None or not np.isfinite(span[i, j]) else f"\n±{span[i, j]:.2g}"
        ax.text(j, i, f"{v:.3g}{spread}", ha="center", va="center", fontsize=9,
                color="r" if over else ink, fontweight="bold" if over else "normal",
                bbox={"facecolor": "w", "alpha": 0.7, "lw": 0} if over else None)


def held_text(spec: SweepSpec) -> str:
    fixed = ", ".join(f"{k}={format_value(v)}" for k, v in spec.fixed)
    return f"scenario {Path(spec.scenario).stem}, {spec.duration_s:g} s per run" + (
        f", fixed: {fixed}" if fixed else ""
    )


def error_against(
    spec: SweepSpec, rows: Sequence[Row], key: str, path: Path
) -> list[np.ndarray]:
    """estimator and radius errors against `key`, one line per estimator, with error bars
    from the lowest to the highest seed; the other axes held at their first value.  The
    error bars drawn, (2, points) each: below and above the mean."""
    xkeys, xs = spec.partners(key), points(spec, key)
    ekeys = spec.partners("estimator") if "estimator" in spec.axes else ()
    estimators = points(spec, "estimator") if ekeys else [()]
    held = [(keys, pts[0]) for keys, pts in spec.grid if keys not in (xkeys, ekeys)]
    kept = [r for r in rows if all(point_of(r, keys) == first for keys, first in held)]
    x = [float(dict(zip(xkeys, pt, strict=True))[key]) for pt in xs]
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.8))
    bars: list[np.ndarray] = []
    for ax, metric in zip(axs, ("estimator_error_m", "radius_error_m"), strict=True):
        for k, est in enumerate(estimators):
            cells = [[r for r in kept if point_of(r, xkeys) == pt and point_of(r, ekeys) == est]
                     for pt in xs]
            ys, yerr = mean_and_bars(cells, metric)
            bars.append(yerr)
            name = point_text(est) if est else dict(spec.fixed).get("estimator", "of the scenario")
            # distinct markers and dashes: equal results must not hide a line
            ax.errorbar(x, ys, yerr=yerr, marker="os^v"[k % 4], ls=("-", "--", ":")[k % 3],
                        lw=1.5, ms=8 - 2 * (k % 3), capsize=4, label=f"estimator: {name}")
        _error_axis(ax, spec, metric, x, [point_text(pt) for pt in xs], "/".join(xkeys))
    held_at = ", ".join(f"{'/'.join(k)}={point_text(p)}" for k, p in held)
    fig.suptitle(
        f"errors against {'/'.join(xkeys)}; mean over {spec.repeats} seed(s), bars: min-max; "
        f"other axes held at their first value: {held_at or 'none'}\n{held_text(spec)}",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return bars


def _error_axis(ax: Axes, spec: SweepSpec, metric: str, x: list[float], ticks: list[str],
                xlabel: str) -> None:
    bound = bound_of(spec, metric)
    if bound is not None:
        ax.axhline(bound, color="k", ls="--", lw=1, label=f"paper's bound {bound:g}")
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(PLAIN)
    ax.yaxis.set_minor_formatter(SPARSE)
    ax.set_xticks(x, ticks)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(STYLE[metric][0])
    ax.set_title(metric)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
