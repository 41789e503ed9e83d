"""links.png: the health of every link over time (delivered ratio and age), with the run's
marks; drawn from links.csv (`deploy.report.link_history`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: runs on headless machines and in CI
import matplotlib.pyplot as plt
import numpy as np

from deploy.report.link_history import LinkColumns
from deploy.report.marks import MAX_LEGEND, Mark, draw_marks, legend_handles

LINKS_PNG = "links.png"


def link_health_figure(
    links: dict[str, LinkColumns], path: Path, marks: Sequence[Mark] = ()
) -> list[Mark]:
    """Per link: delivered ratio and mean age at delivery over each status interval (about
    1 s); `marks` on both panels.  The marks drawn."""
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(12, 7.5), sharex=True)
    positive_age = False
    for name, cols in sorted(links.items()):
        t = np.asarray(cols["t_s"])
        (line,) = top.plot(t, cols["delivered"], lw=1.0, marker=".", ms=3, label=name)
        age = np.asarray(cols["age_mean_ms"])
        bottom.plot(t, age, lw=1.0, marker=".", ms=3, color=line.get_color(), label=name)
        positive_age |= bool(np.any(np.isfinite(age) & (age > 0)))
    top.set_ylabel("delivered ratio (per interval)")
    top.set_ylim(-0.03, 1.05)
    top.set_title(f"link health: {len(links)} links (receiver's counters, ~1 s intervals)")
    bottom.set_ylabel("mean age at delivery [ms]")
    if positive_age:
        bottom.set_yscale("log")
    bottom.set_xlabel("t [s]")
    drawn: list[Mark] = []
    for ax in (top, bottom):
        ax.grid(alpha=0.3, which="both")
        drawn = draw_marks(ax, marks)
    if 0 < len(links) <= MAX_LEGEND:
        top.legend(loc="lower left", fontsize=8, ncol=max(1, math.ceil(len(links) / 4)))
    if drawn:
        bottom.legend(handles=legend_handles(drawn), loc="upper right", fontsize=8)
    if not links:
        top.text(0.5, 0.5, "no link counters were recorded", ha="center", va="center",
                 transform=top.transAxes)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return drawn
