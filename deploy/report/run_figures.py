"""The paper's six performance panels and the trajectory plot, as PNG files, with the
run's marks (faults, pauses, deaths, restarts, membership changes: `deploy.report.marks`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only: runs on headless machines and in CI
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes

from agents.analysis.metrics import ErrorSeries
from agents.analysis.timeseries import RunSeries
from deploy.report.marks import MAX_LEGEND, STYLE, Mark, draw_marks, legend_handles

PANELS = (
    ("z_m", "z_i = rho'_i - rho_d [m]", "estimated radius error"),
    ("delta", "delta_i", "estimated included-angle error"),
    ("estimator_error_m", "|r_i - LAP| [m]", "estimator error"),
    ("e_rho_m", "e_rho,i [m]", "real radius error"),
    ("e_delta", "e_delta,i", "real included-angle error"),
)


def _plot_followers(ax: Axes, t: np.ndarray, values: np.ndarray, label: str) -> None:
    n = values.shape[1]
    for i in range(n):
        ax.plot(t, values[:, i], **_follower_style(i, n, f"{label}{i + 1}", 1.0))


def _follower_style(i: int, n: int, label: str, lw: float) -> dict[str, Any]:
    """Follower i's line: named in the legend, or in a large swarm one colour scale over
    the ring (and thinner lines) instead of a legend entry each."""
    if n <= MAX_LEGEND:
        return {"lw": lw, "label": label}
    return {"lw": 0.7 * lw, "color": plt.get_cmap("viridis")(i / max(1, n - 1))}


def _follower_key(ax: Axes, n: int) -> None:
    """The legend of the followers' lines: names up to MAX_LEGEND, else a colour bar."""
    if n <= MAX_LEGEND:
        ax.legend(loc="upper right", fontsize=8)
        return
    scale = plt.cm.ScalarMappable(cmap="viridis", norm=plt.Normalize(1, n))
    bar = ax.figure.colorbar(scale, ax=ax, pad=0.01, fraction=0.04)
    bar.set_label("follower", fontsize=8)


def performance_figure(
    series: RunSeries,
    errors: ErrorSeries,
    eps: tuple[float, float],
    path: Path,
    marks: Sequence[Mark] = (),
) -> list[Mark]:
    """The six panels, `marks` on every one; the marks drawn."""
    fig, axes = plt.subplots(3, 2, figsize=(12, 10), sharex=True)
    t = series.t_s
    for ax, (field, ylabel, title) in zip(axes.flat, PANELS, strict=False):
        _plot_followers(ax, t, getattr(errors, field), "F")
        ax.set_title(title)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    for ax, bound in ((axes.flat[2], eps[0]), (axes.flat[3], eps[0]), (axes.flat[4], eps[1])):
        ax.axhline(bound, color="k", ls="--", lw=0.8)
        if ax is not axes.flat[2]:
            ax.axhline(-bound, color="k", ls="--", lw=0.8)
    axes.flat[2].set_yscale("log")
    cmd = axes.flat[5]
    speed = np.linalg.norm(series.command_m_s, axis=2)
    _plot_followers(cmd, t, speed, "|u|")
    cmd.set_title("control commands")
    cmd.set_ylabel("|u_i| [m/s]")
    cmd.grid(alpha=0.3)
    drawn: list[Mark] = []
    for ax in axes.flat:
        drawn = draw_marks(ax, marks)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    _follower_key(axes.flat[0], errors.e_rho_m.shape[1])
    if drawn:
        axes.flat[5].legend(handles=legend_handles(drawn), loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return drawn


def trajectory_figure(
    series: RunSeries, rho_d_m: float, path: Path, marks: Sequence[Mark] = ()
) -> list[Mark]:
    """Tracks, the LAP and the final circle; each mark where its follower (all followers
    for a mark about another process) was at that time.  The marks drawn."""
    xy_all = np.concatenate(
        [series.follower_pos_m.reshape(-1, 2), series.target_pos_m.reshape(-1, 2)]
    )
    span = np.ptp(xy_all, axis=0) + 1.0
    # Size the canvas to the data's aspect so long tracks are not a thin strip.
    fig, ax = plt.subplots(figsize=(12, float(np.clip(12 * span[1] / span[0] + 1.5, 4, 11))))
    n = series.follower_pos_m.shape[1]
    for i in range(n):
        xy = series.follower_pos_m[:, i]
        ax.plot(xy[:, 0], xy[:, 1], **_follower_style(i, n, f"follower {i + 1}", 0.9))
        ax.plot(*xy[0], "o", ms=4, color=ax.lines[-1].get_color())
    for j in range(series.target_pos_m.shape[1]):
        xy = series.target_pos_m[:, j]
        ax.plot(xy[:, 0], xy[:, 1], "--", lw=0.8, color="0.4")
    lap = series.lap_m
    ax.plot(lap[:, 0], lap[:, 1], "k-", lw=1.5, label="LAP (true)")
    circle = plt.Circle(tuple(lap[-1]), rho_d_m, fill=False, ls=":", color="k")
    ax.add_patch(circle)
    ax.plot(series.follower_pos_m[-1, :, 0], series.follower_pos_m[-1, :, 1], "k^", ms=7)
    drawn = _mark_positions(ax, series, marks)
    ax.set_aspect("equal")
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")
    ax.set_title(f"trajectories over {series.t_s[-1] - series.t_s[0]:.0f} s (dashed: targets)")
    ax.grid(alpha=0.3)
    if n <= MAX_LEGEND:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    else:  # the colour bar takes the right-hand side
        ax.legend(loc="upper left", fontsize=8)
        _follower_key(ax, n)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return drawn


MARKERS = {"membership": "D", "fault": "X", "died": "x", "restart": "P", "pause": "s",
           "network": "v"}


def _mark_positions(ax: Axes, series: RunSeries, marks: Sequence[Mark]) -> list[Mark]:
    drawn, labelled = [], set()
    t = series.t_s
    for m in marks:
        if len(t) == 0 or not t[0] <= m.t_s <= t[-1]:
            continue
        k = min(int(np.searchsorted(t, m.t_s)), len(t) - 1)
        n = series.follower_pos_m.shape[1]
        who = [m.follower] if m.follower is not None and m.follower < n else range(n)
        xy = series.follower_pos_m[k, list(who)]
        label = STYLE[m.kind][2] if m.kind not in labelled else None
        labelled.add(m.kind)
        ax.plot(xy[:, 0], xy[:, 1], MARKERS[m.kind], color=STYLE[m.kind][0], ms=9, mfc="none",
                mew=1.6, ls="none", label=label)
        drawn.append(m)
    return drawn
