"""Mean and spread over the seeds of each grid point (sweeps with `repeats` > 1).

`results_summary.csv` has one row per grid point: how many seeds ran and finished, then
for each metric its mean and its sample standard deviation (ddof = 1) over the finished
seeds that gave a value.  `settled` counts the seeds that settled at all (a run that never
settles has no settle time, and leaving it out of the mean alone would flatter the point).
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from pathlib import Path

from deploy.sweep.spec import SweepSpec
from deploy.sweep.table import DELIVERED, METRICS, RECOVERY, Row, write_csv_atomic
from deploy.sweep.values import Value, format_value

SUMMARY_CSV = "results_summary.csv"


def metrics_of(rows: Sequence[Row]) -> tuple[str, ...]:
    extra = tuple(k for k in (DELIVERED, RECOVERY) if any(k in r.state.metrics for r in rows))
    return (*METRICS, *extra)


def groups(rows: Sequence[Row]) -> dict[tuple[tuple[str, Value], ...], list[Row]]:
    """Rows by grid point, in table order."""
    out: dict[tuple[tuple[str, Value], ...], list[Row]] = {}
    for row in rows:
        out.setdefault(row.cell.values, []).append(row)
    return out


def mean_spread(values: Sequence[float]) -> tuple[float | None, float | None]:
    if not values:
        return None, None
    spread = statistics.stdev(values) if len(values) > 1 else None
    return statistics.fmean(values), spread


def summary(spec: SweepSpec, rows: Sequence[Row]) -> tuple[list[str], list[dict[str, str]]]:
    """(columns, one row of text per grid point)."""
    metrics = metrics_of(rows)
    cols = [*spec.axes, "seeds", "done", "settled"]
    cols += [f"{m}_{s}" for m in metrics for s in ("mean", "std")]
    table = []
    for point, group in groups(rows).items():
        done = [r for r in group if r.state.done]
        out = {k: format_value(v) for k, v in point}
        settled = [r for r in done if r.state.metrics.get("settle_time_s") is not None]
        out.update(seeds=str(len(group)), done=str(len(done)), settled=str(len(settled)))
        for m in metrics:
            values = [v for r in done if (v := r.state.metrics.get(m)) is not None]
            for stat, v in zip(("mean", "std"), mean_spread(values), strict=True):
                out[f"{m}_{stat}"] = "" if v is None else f"{v:.6g}"
        table.append(out)
    return cols, table


def write_summary(spec: SweepSpec, rows: Sequence[Row], md_path: Path) -> Path:
    """`results_summary.csv`, and its table (mean ± std) appended to results.md."""
    cols, table = summary(spec, rows)
    path = spec.out / SUMMARY_CSV
    write_csv_atomic(path, cols, table)
    metrics = metrics_of(rows)
    shown = [*spec.axes, "done", "settled", *metrics]
    lines = [
        "",
        f"## Mean ± standard deviation over {spec.repeats} seeds (finished cells)",
        "",
        "| " + " | ".join(shown) + " |",
        "|" + "---|" * len(shown),
    ]
    for row in table:
        cells = [row[k] for k in (*spec.axes, "done", "settled")]
        cells += [_pm(row[f"{m}_mean"], row[f"{m}_std"]) for m in metrics]
        lines.append("| " + " | ".join(cells) + " |")
    with open(md_path, "a") as f:
        f.write("\n".join(lines) + "\n")
    return path


def _pm(mean: str, std: str) -> str:
    if not mean:
        return "-"
    short = f"{float(mean):.4g}"
    return f"{short} ± {float(std):.2g}" if std else short
