"""The figure of a counterfactual replay: the run's and the other law's command and
estimate of one follower, with the run's marks (deploy.report.marks)."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from agents.follower.journal_replay import Series
from deploy.report.marks import draw_marks, legend_handles, run_marks


def counterfactual_figure(run: Series, series: Series, start_s: float, run_dir: Path,
                          follower: int, label: str, out: Path) -> Path:
    """Command and estimate, `run` (the run's law replayed) vs `series` (`label`), x and
    y, on the run's time axis (from `start_s`, the start on the follower's clock; a
    journal without it starts at its first control tick)."""
    t0 = start_s if math.isfinite(start_s) else (series.t_s[0] if series.t_s else 0.0)
    t = [x - t0 for x in series.t_s]
    marks = run_marks(run_dir, [x - t0 for x in series.regroups_s])
    fig, axes = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    rows = ((axes[0], run.u_m_s, series.u_m_s, "command (m/s)"),
            (axes[1], run.r_m, series.r_m, "estimate of the centre (m)"))
    for ax, ran, other, ylabel in rows:
        for part, colour in (("real", "tab:blue"), ("imag", "tab:orange")):
            axis = "x" if part == "real" else "y"
            ax.plot(t, [getattr(v, part) for v in ran], color=colour, lw=1.2,
                    label=f"{axis}: the run")
            ax.plot(t, [getattr(v, part) for v in other], color=colour, lw=1.2, ls="--",
                    label=f"{axis}: {label}")
        drawn = draw_marks(ax, marks)
        handles, _ = ax.get_legend_handles_labels()
        ax.legend(handles=[*handles, *legend_handles(drawn)], fontsize=8, loc="upper right")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    axes[0].set_title(f"follower-{follower}: the run and {label}, on the same inputs (open loop)")
    axes[1].set_xlabel("time from the start (s)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
