"""What happened during a run, as marks on its figures: faults, pauses, deaths, restarts
and membership changes.

Sources: the launcher's timeline (launch.json "events", `deploy.launch.fault_injector` and
`deploy.procs.restarts`; the launcher writes it before the stop word so that the recorder can
draw it) and the membership changes the recorder saw (metrics.json "membership").  Times
are seconds from the experiment's start, like series.csv.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from matplotlib.axes import Axes
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

LAUNCH_FILE = "launch.json"
# More lines than this get no legend entry each: a legend of 32 or 64 names is taller than
# its panel, and tight_layout then squeezes every panel of the figure to a strip.
MAX_LEGEND = 12
# kind -> (colour, line style, legend text)
STYLE: dict[str, tuple[str, str, str]] = {
    "membership": ("tab:red", ":", "membership change"),
    "fault": ("black", "-.", "fault injected"),
    "died": ("tab:purple", "--", "process died"),
    "restart": ("tab:green", "--", "process (re)started"),
    "pause": ("tab:orange", "-", "process paused"),
    "network": ("tab:cyan", "-", "network fault"),
}
BANDS = ("pause", "network")


@dataclass(frozen=True)
class Mark:
    t_s: float
    kind: str  # a key of STYLE
    process: str = ""  # "follower-1", "sim", ... ("" for membership changes)
    end_s: float | None = None  # a pause's end: drawn as a band

    @property
    def follower(self) -> int | None:
        """The 0-based follower this mark is about, if it is about one."""
        head, _, tail = self.process.partition("-")
        return int(tail) if head == "follower" and tail.isdigit() else None


def membership_marks(times_s: Sequence[float]) -> list[Mark]:
    return [Mark(float(t), "membership") for t in times_s]


def _event_mark(e: dict[str, Any]) -> Mark | None:
    t, proc, event = float(e["t_s"]), str(e.get("process", "")), e.get("event")
    if event == "fault" and e.get("action") == "pause":
        return Mark(t, "pause", proc, t + float(e.get("duration_s") or 0.0))
    if event == "fault":
        return Mark(t, "fault", proc)
    if event == "died":
        return Mark(t, "died", proc)
    if event in ("restarted", "started"):
        return Mark(t, "restart", proc)
    return None  # "resumed": the end of a pause band


def event_marks(launch: dict[str, Any] | None) -> list[Mark]:
    """Marks from launch.json's "events" (malformed rows are skipped)."""
    marks = []
    for e in (launch or {}).get("events") or []:
        try:
            mark = _event_mark(e)
        except (KeyError, TypeError, ValueError, AttributeError):
            continue
        if mark is not None:
            marks.append(mark)
    return marks


def read_launch(run_dir: Path) -> dict[str, Any] | None:
    try:
        doc = json.loads((run_dir / LAUNCH_FILE).read_text())
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) else None


def run_marks(run_dir: Path, membership_s: Sequence[float],
              net_faults: Sequence[tuple[str, float, float]] = ()) -> list[Mark]:
    """Every mark of a run directory, in time order; `net_faults` (label, at_s, end_s)
    from run.json: bands."""
    marks = membership_marks(membership_s) + event_marks(read_launch(run_dir))
    marks += [Mark(at_s, "network", label, end_s) for label, at_s, end_s in net_faults]
    return sorted(marks, key=lambda m: m.t_s)


def draw_marks(ax: Axes, marks: Sequence[Mark]) -> list[Mark]:
    """Vertical lines (bands for pauses) on a time axis; the marks drawn."""
    for m in marks:
        colour, style, _ = STYLE[m.kind]
        if m.end_s is not None and m.end_s > m.t_s:
            ax.axvspan(m.t_s, m.end_s, color=colour, alpha=0.15, lw=0, label=f"_{m.kind}")
        else:
            ax.axvline(m.t_s, color=colour, ls=style, lw=1.0, label=f"_{m.kind}")
    return list(marks)


def legend_handles(marks: Sequence[Mark]) -> list[Line2D | Patch]:
    """One legend entry per kind of mark present."""
    handles: list[Line2D | Patch] = []
    for kind in dict.fromkeys(m.kind for m in marks):
        colour, style, text = STYLE[kind]
        if kind in BANDS:
            handles.append(Patch(color=colour, alpha=0.3, label=text))
        else:
            handles.append(Line2D([], [], color=colour, ls=style, label=text))
    return handles
