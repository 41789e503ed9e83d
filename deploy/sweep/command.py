"""`enclose sweep SWEEP_FILE`: a grid of real `enclose run`s, resumable; one after the other
by default, `--jobs N` at a time here (deploy.sweep.parallel), or on a Dask cluster
(`--cluster`, deploy.sweep.cluster).

Each cell has its own run directory under the sweep directory; a cell whose directory holds
good metrics and clean exit codes is done and skipped on the next invocation. The table and
figures are rebuilt from the cell directories every time, so a resumed sweep and
`--report-only` give the same results.
"""

from __future__ import annotations

import argparse
import itertools
import json
import logging
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rich.console import Console

from deploy.json_files import read_json
from deploy.procs.interrupts import interrupts
from deploy.sweep.cell_runner import HOST_FILE, CellRunner, SubprocessRunner
from deploy.sweep.figure_by_law import law_figures
from deploy.sweep.figures import write_figures
from deploy.sweep.parallel import StopSignals, run_parallel
from deploy.sweep.spec import Cell, SweepSpec, load_sweep
from deploy.sweep.summary import write_summary
from deploy.sweep.sweep_progress import SweepProgress
from deploy.sweep.sweep_verdict import print_sweep_verdict
from deploy.sweep.table import RECORD, CellState, cell_state, collect, write_tables
from errors import ConfigError

log = logging.getLogger("enclose.sweep")
STARTUP_S = 15.0  # a cell's start-up and shutdown, for the ETA before any cell has run
TIMEOUT_MARGIN_S = 300.0  # link wait (up to 120 s) + recorder writing (up to 120 s) + slack


def register(sub: Any) -> None:
    p = sub.add_parser(
        "sweep",
        help="a grid of real runs over network settings and laws: resumable, table and figures",
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
    p.add_argument(
        "--jobs",
        type=int,
        default=None,
        metavar="N",
        help="cells at a time (default: 1 here; with --cluster, one per worker thread); "
        "parallel cells share the CPU, which changes their results",
    )
    p.add_argument(
        "--cluster",
        default=None,
        metavar="ADDRESS",
        help="run the cells on a Dask distributed scheduler (tcp://host:8786); needs the "
        "`cluster` extra",
    )
    p.set_defaults(func=_main)


@dataclass(frozen=True)
class SweepOptions:
    """`enclose sweep`'s command line."""

    sweep_file: Path
    out: Path | None = None  # None: the file's `out`
    report_only: bool = False
    list: bool = False
    cell_timeout_s: float | None = None  # None: duration + TIMEOUT_MARGIN_S
    jobs: int | None = None  # None: 1 here, one per worker thread on a cluster
    cluster: str | None = None  # a Dask scheduler's address

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> SweepOptions:
        return cls(args.sweep_file, args.out, args.report_only, args.list, args.cell_timeout,
                   args.jobs, args.cluster)


def _main(args: argparse.Namespace) -> int:
    return sweep(SweepOptions.from_namespace(args))


def sweep(opts: SweepOptions) -> int:
    spec = load_sweep(opts.sweep_file, opts.out.resolve() if opts.out else None)
    if opts.jobs is not None and opts.jobs < 1:
        raise ConfigError("--jobs", f"must be >= 1, got {opts.jobs}")
    if opts.list:
        for row in collect(spec):
            print(f"{row.state.status:11s} {row.cell.name}")
        return 0
    if opts.report_only:
        report(spec)
        return 0
    with interrupts():  # SIGTERM stops as cleanly as Ctrl-C
        if opts.cluster:
            return _on_cluster(spec, opts.cluster, opts)
        return run_sweep(spec, timeout_s=opts.cell_timeout_s, jobs=opts.jobs or 1)


def _on_cluster(spec: SweepSpec, address: str, opts: SweepOptions) -> int:
    from deploy.sweep.cluster import ClusterRunner, connect  # the optional extra

    signals = StopSignals()
    with connect(address) as client:
        runner = ClusterRunner(client, signals)
        jobs = opts.jobs or runner.capacity()
        return run_sweep(
            spec, runner, opts.cell_timeout_s, jobs=jobs, signals=signals, where=address
        )


def run_sweep(
    spec: SweepSpec,
    runner: CellRunner | None = None,
    timeout_s: float | None = None,
    tty: bool | None = None,
    figures: bool = True,
    jobs: int = 1,
    signals: StopSignals | None = None,
    where: str = "local",
) -> int:
    """Run every cell not done yet, `jobs` at a time; 0 if all are done, 1 if some failed,
    130 if interrupted.  `where` ("local" or a cluster address) goes into each record."""
    cells = spec.cells()
    todo = [c for c in cells if not _state(spec, c).done]
    progress = SweepProgress(len(cells), spec.duration_s + STARTUP_S, tty, jobs)
    progress.skipped(len(cells) - len(todo))
    signals = signals or StopSignals()
    tick = progress.draw if jobs == 1 else signals.tick  # parallel: the main thread draws
    runner = runner or SubprocessRunner(tick=tick, kill_now=signals.kill_now)
    timeout = timeout_s or spec.duration_s + TIMEOUT_MARGIN_S
    log.info(
        "sweep %s: %d cells, %d done already, %d to run (%d at a time, %s), in %s",
        spec.path.name, len(cells), len(cells) - len(todo), len(todo), jobs, where, spec.out,
    )
    if jobs > 1:
        warn_contention(jobs, where)
    job = _cell_job(spec, runner, timeout, progress, {"jobs": jobs, "where": where})
    try:
        if jobs == 1:
            failed = [cell.name for cell in todo if not job(cell)]
        else:
            failed = run_parallel(todo, job, jobs, signals, progress.draw)
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


def _cell_job(
    spec: SweepSpec,
    runner: CellRunner,
    timeout_s: float,
    progress: SweepProgress,
    context: dict[str, Any],
) -> Callable[[Cell], bool]:
    """Run one cell with progress; True when it is done (callable from several threads)."""
    positions = itertools.count(progress.finished + 1)

    def job(cell: Cell) -> bool:
        progress.begin(next(positions), cell.label())
        code, wall_s = run_one(spec, runner, cell, timeout_s, context)
        progress.end(wall_s)
        done = _state(spec, cell).done
        if not done:
            log.warning("cell %s failed (exit code %s): see its folder", cell.name, code)
        return done

    return job


def warn_contention(jobs: int, where: str) -> None:
    if where == "local":
        log.warning(
            "%d cells at a time on %s cores: they share the CPU, which changes their results "
            "(the table records jobs and load); --jobs 1 (the default) for figures to compare",
            jobs, os.cpu_count(),
        )
    else:
        log.warning(
            "%d cells at a time on the cluster: each worker thread runs a whole swarm; give "
            "workers --nthreads 1 per spare core or so (the table records host, jobs and load)",
            jobs,
        )


def _state(spec: SweepSpec, cell: Cell) -> CellState:
    cell_dir = spec.out / cell.name
    return cell_state(cell_dir, spec.run_argv(cell, cell_dir))


def run_one(
    spec: SweepSpec,
    runner: CellRunner,
    cell: Cell,
    timeout_s: float,
    context: dict[str, Any] | None = None,
) -> tuple[int, float]:
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
        **(context or {}),
        "started_wall_s": time.time(),
        "exit_code": None,
    }
    _write_record(cell_dir, record)
    t0, code = time.monotonic(), 130
    try:
        code = runner.run_cell(argv, cell_dir, timeout_s)
    finally:
        record.update(exit_code=code, wall_s=time.monotonic() - t0)
        record.update(read_json(cell_dir / HOST_FILE) or {})
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
    if spec.repeats > 1:
        path = write_summary(spec, rows, md_path)
        log.info("mean and spread over %d seeds: %s", spec.repeats, path.name)
    finished = [r for r in rows if r.state.done]
    paths = [*write_figures(spec, finished), *law_figures(spec, finished)] if figures else []
    print_sweep_verdict(Console(), spec, rows, paths)
