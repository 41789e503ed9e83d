"""`enclose sweep SWEEP_FILE`: a grid of real `enclose run`s, one after the other, resumable.

Each cell has its own run directory under the sweep directory; a cell whose directory holds
good metrics and clean exit codes is done and skipped on the next invocation. The table and
figures are rebuilt from the cell directories every time, so a resumed sweep and
`--report-only` give the same results.
"""

from __future__ import annotations

import argparse
import json
import logging
import shutil
import signal
import time
from pathlib import Path
from types import FrameType
from typing import Any

from rich.console import Console

from deploy.sweep_figures import write_figures
from deploy.sweep_runner import CellRunner, SubprocessRunner, SweepProgress
from deploy.sweep_spec import Cell, SweepSpec, load_sweep
from deploy.sweep_table import RECORD, CellState, cell_state, collect, write_tables
from deploy.sweep_verdict import print_sweep_verdict

log = logging.getLogger("enclose.sweep")
STARTUP_S = 15.0  # a cell's start-up and shutdown, for the ETA before any cell has run
TIMEOUT_MARGIN_S = 300.0  # link wait (up to 120 s) + recorder writing (up to 120 s) + slack


def register(sub: Any) -> None:
    p = sub.add_parser(
        "sweep", help="a grid of real runs over network settings: resumable, table and figures"
    )
    p.add_argument("sweep_file", type=Path, help="sweep TOML file (see bench/sweeps/)")
    p.add_argument("--out", type=Path, default=None, help="sweep directory (default: file's out)")
    p.add_argument(
        "--report-only", action="store_true", help="only rebuild the table and figures"
    )
    p.add_argument("--list", action="store_true", help="print the cells and their state, run none")
    p.add_argument(
        "--cell-timeout",
        type=float,
        default=None,
        help=f"seconds before a cell is stopped (default: duration + {TIMEOUT_MARGIN_S:.0f})",
    )
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    spec = load_sweep(args.sweep_file, args.out.resolve() if args.out else None)
    if args.list:
        for row in collect(spec):
            print(f"{row.state.status:11s} {row.cell.name}")
        return 0
    code = 0
    if not args.report_only:
        previous = signal.signal(signal.SIGTERM, _interrupt)  # stop as cleanly as on Ctrl-C
        try:
            code = run_sweep(spec, timeout_s=args.cell_timeout)
        finally:
            signal.signal(signal.SIGTERM, previous)
    else:
        report(spec)
    return code


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


def run_sweep(
    spec: SweepSpec,
    runner: CellRunner | None = None,
    timeout_s: float | None = None,
    tty: bool | None = None,
    figures: bool = True,
) -> int:
    """Run every cell not done yet; 0 if all are done, 1 if some failed, 130 if interrupted."""
    cells = spec.cells()
    todo = [c for c in cells if not _state(spec, c).done]
    progress = SweepProgress(len(cells), spec.duration_s + STARTUP_S, tty)
    progress.skipped(len(cells) - len(todo))
    runner = runner or SubprocessRunner(tick=progress.draw)
    timeout = timeout_s or spec.duration_s + TIMEOUT_MARGIN_S
    log.info(
        "sweep %s: %d cells, %d done already, %d to run, in %s",
        spec.path.name,
        len(cells),
        len(cells) - len(todo),
        len(todo),
        spec.out,
    )
    failed: list[str] = []
    try:
        for k, cell in enumerate(todo):
            progress.begin(len(cells) - len(todo) + k + 1, cell.label())
            code, wall_s = run_one(spec, runner, cell, timeout)
            progress.end(wall_s)
            if not _state(spec, cell).done:
                failed.append(cell.name)
                log.warning("cell %s failed (exit code %s): see its folder", cell.name, code)
    except KeyboardInterrupt:
        progress.close()
        log.warning("sweep interrupted: finished cells are kept; run the same command to resume")
        report(spec, figures)
        return 130
    progress.close()
    report(spec, figures)
    if failed:
        log.warning("%d of %d cells failed: %s", len(failed), len(todo), ", ".join(failed))
    return 1 if failed else 0


def _state(spec: SweepSpec, cell: Cell) -> CellState:
    cell_dir = spec.out / cell.name
    return cell_state(cell_dir, spec.run_argv(cell, cell_dir))


def run_one(spec: SweepSpec, runner: CellRunner, cell: Cell, timeout_s: float) -> tuple[int, float]:
    """One cell from scratch (what a failed or interrupted attempt left is removed first)."""
    cell_dir = spec.out / cell.name
    if cell_dir.exists():
        shutil.rmtree(cell_dir)
    cell_dir.mkdir(parents=True)
    argv = spec.run_argv(cell, cell_dir)
    record: dict[str, Any] = {
        "cell": cell.name,
        "values": {k: v for k, v in cell.values},
        "seed": cell.seed,
        "argv": argv,
        "started_wall_s": time.time(),
        "exit_code": None,
    }
    _write_record(cell_dir, record)
    t0, code = time.monotonic(), 130
    try:
        code = runner.run_cell(argv, cell_dir, timeout_s)
    finally:
        record.update(exit_code=code, wall_s=time.monotonic() - t0)
        _write_record(cell_dir, record)
    return code, record["wall_s"]


def _write_record(cell_dir: Path, record: dict[str, Any]) -> None:
    tmp = cell_dir / (RECORD + ".tmp")
    tmp.write_text(json.dumps(record, indent=2) + "\n")
    tmp.replace(cell_dir / RECORD)


def report(spec: SweepSpec, figures: bool = True) -> None:
    """Table and figures from the cell directories as they are now."""
    rows = collect(spec)
    csv_path, md_path = write_tables(spec, rows)
    done = sum(r.state.done for r in rows)
    log.info("%d/%d cells done; table %s and %s", done, len(rows), csv_path, md_path.name)
    paths = write_figures(spec, [r for r in rows if r.state.done]) if figures else []
    print_sweep_verdict(Console(), spec, rows, paths)
