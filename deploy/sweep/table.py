"""State of each sweep cell, read from its directory; the results table (CSV and Markdown)."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from deploy.json_files import read_json
from deploy.report.verdict import silent_followers
from deploy.sweep.spec import Cell, SweepSpec
from deploy.sweep.values import format_value

RECORD = "sweep_cell.json"  # written by the sweep: the cell's argv, exit code, wall time
METRICS = ("estimator_error_m", "radius_error_m", "angle_error", "settle_time_s",
           "command_jump_m_s", "min_separation_m")
DELIVERED = "delivered_ratio"
# The slowest recovery over a cell's network faults (metrics.json "net_faults"); empty
# when one never came back inside the bounds, or the cell had none.
RECOVERY = "net_fault_recovery_s"
INTERRUPTED_EXIT = 130
RUN_COLUMNS = ("wall_s", "jobs", "load_1min", "host")


@dataclass(frozen=True)
class CellState:
    status: str  # done | failed | silent | interrupted | timeout | incomplete | stale | pending
    exit_code: int | None = None
    wall_s: float | None = None
    metrics: dict[str, float | None] = field(default_factory=dict)
    # Where and how it ran: cells side by side share the CPU, which changes the results.
    jobs: int | None = None
    load_1min: float | None = None  # mean 1-minute load average of its machine during the run
    host: str | None = None

    @property
    def done(self) -> bool:
        return self.status == "done"


def comparable(argv: list[str]) -> list[str]:
    """argv without the --out value, so that a moved sweep folder still counts as the same."""
    out: list[str] = []
    skip = False
    for arg in argv:
        if not skip and arg != "--out":
            out.append(arg)
        skip = arg == "--out"
    return out


def launch_ok(launch: dict[str, Any] | None) -> bool:
    procs = (launch or {}).get("processes")
    return (
        isinstance(procs, dict)
        and bool(procs)
        and all(isinstance(p, dict) and p.get("exit_code") == 0 for p in procs.values())
    )


def cell_state(cell_dir: Path, argv: list[str]) -> CellState:
    if not cell_dir.is_dir():
        return CellState("pending")
    record = read_json(cell_dir / RECORD) or {}
    if "argv" in record and comparable(list(record["argv"])) != comparable(argv):
        return CellState("stale")
    metrics_doc = read_json(cell_dir / "metrics.json")
    ok_metrics = metrics_doc is not None and "error" not in metrics_doc
    metrics = pick_metrics(metrics_doc) if ok_metrics and metrics_doc else {}
    code, wall = record.get("exit_code"), record.get("wall_s")
    # A run stopped by Ctrl-C also ends with clean exit codes: its own exit code tells.
    finished = code in (0, None) and not (metrics_doc or {}).get("stopped_early")
    # A follower that sent no state leaves metrics of the others only: run it again.
    silent = bool(silent_followers(metrics_doc or {}))
    if ok_metrics and finished and launch_ok(read_json(cell_dir / "launch.json")):
        status = "silent" if silent else "done"
    elif code == INTERRUPTED_EXIT:
        status = "interrupted"
    elif code == 124:
        status = "timeout"
    elif code is not None:
        status = "failed"
    else:
        status = "incomplete"
    jobs, host = record.get("jobs"), record.get("host")
    return CellState(
        status, code, wall, metrics,
        jobs=jobs if isinstance(jobs, int) else None,
        load_1min=number(record.get("load_1min_mean")),
        host=host if isinstance(host, str) else None,
    )


def pick_metrics(doc: dict[str, Any]) -> dict[str, float | None]:
    out: dict[str, float | None] = {key: number(doc.get(key)) for key in METRICS}
    ratio = mean_delivered(doc.get("links"))
    if ratio is not None:
        out[DELIVERED] = ratio
    faults = doc.get("net_faults")
    if isinstance(faults, list) and faults:
        times = [number(f.get("recovery_s")) if isinstance(f, dict) else None for f in faults]
        out[RECOVERY] = None if None in times else max(t for t in times if t is not None)
    return out


def number(raw: Any) -> float | None:
    if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw):
        return None
    return float(raw)


def mean_delivered(links: Any) -> float | None:
    """Mean `delivered_ratio` over the follower-to-follower links of metrics.json's "links"
    (`"f0->f2"`; the simulator's `"sensor->f2"` links are not the impaired peer links)."""
    if not isinstance(links, dict):
        return None
    peers = [v for k, v in links.items() if not str(k).startswith("sensor")]
    ratios = [number(x.get(DELIVERED)) for x in peers if isinstance(x, dict)]
    valid = [r for r in ratios if r is not None]
    return sum(valid) / len(valid) if valid else None


@dataclass(frozen=True)
class Row:
    cell: Cell
    state: CellState


def collect(spec: SweepSpec) -> list[Row]:
    return [
        Row(c, cell_state(spec.out / c.name, spec.run_argv(c, spec.out / c.name)))
        for c in spec.cells()
    ]


def columns(spec: SweepSpec, rows: list[Row]) -> list[str]:
    extra = [k for k in (DELIVERED, RECOVERY) if any(k in r.state.metrics for r in rows)]
    return [*spec.axes, "seed", "status", "exit_code", *METRICS, *extra, *RUN_COLUMNS, "cell"]


def row_values(spec: SweepSpec, row: Row, cols: list[str], digits: int = 6) -> dict[str, str]:
    values = dict(row.cell.values)
    s = row.state
    out = {k: format_value(values[k]) for k in spec.axes}
    out.update(seed=str(row.cell.seed), status=s.status, cell=row.cell.name)
    out["exit_code"] = "" if s.exit_code is None else str(s.exit_code)
    out["wall_s"] = "" if s.wall_s is None else f"{s.wall_s:.1f}"
    out["jobs"] = "" if s.jobs is None else str(s.jobs)
    out["load_1min"] = "" if s.load_1min is None else f"{s.load_1min:.2f}"
    out["host"] = s.host or ""
    for key in (*METRICS, DELIVERED, RECOVERY):
        if key in cols:
            v = s.metrics.get(key)
            out[key] = "" if v is None else f"{v:.{digits}g}"
    return out


def write_tables(spec: SweepSpec, rows: list[Row]) -> tuple[Path, Path]:
    cols = columns(spec, rows)
    table = [row_values(spec, r, cols) for r in rows]
    spec.out.mkdir(parents=True, exist_ok=True)
    csv_path, md_path = spec.out / "results.csv", spec.out / "results.md"
    write_csv_atomic(csv_path, cols, table)
    short = [row_values(spec, r, cols, digits=4) for r in rows]
    md_path.write_text(markdown(spec, rows, cols, short))
    return csv_path, md_path


def markdown(spec: SweepSpec, rows: list[Row], cols: list[str], table: list[dict[str, str]]) -> str:
    done = sum(r.state.done for r in rows)
    head = [
        f"# Sweep {spec.path.name}",
        "",
        f"Scenario `{Path(spec.scenario).name}`, {format_value(spec.duration_s)} s per run, "
        f"{done}/{len(rows)} cells done. Bounds: {spec.eps_rho_m} m (errors in metres), "
        f"{spec.eps_delta} (angle_error).",
    ]
    if spec.fixed:
        head.append("Fixed: " + ", ".join(f"{k}={format_value(v)}" for k, v in spec.fixed) + ".")
    shown = [c for c in cols if c != "cell"]
    lines = ["| " + " | ".join(shown) + " |", "|" + "---|" * len(shown)]
    lines += ["| " + " | ".join(r[c] or "-" for c in shown) + " |" for r in table]
    return "\n".join([*head, "", *lines, ""])


def write_csv_atomic(path: Path, cols: Sequence[str], table: Sequence[dict[str, Any]]) -> None:
    """A CSV that a reader never sees half-written (a sweep may be resumed or read any time)."""
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(cols))
        writer.writeheader()
        writer.writerows(table)
    tmp.replace(path)
