"""Cost of the launcher's live board and of the verdict (issue 14): what a redraw takes in
the launcher's loop, which also times faults and repeats the start word.

Renders the board (as a terminal would get it) for swarms of 4 and 16 followers, and reads
and prints a run directory's verdict, each `--repeat` times; prints the median in ms.

Run:
    python bench/bench_board.py [--repeat 200] [--run-dir RUN_DIR]
"""

from __future__ import annotations

import argparse
import io
import statistics
import time
from collections.abc import Callable
from pathlib import Path

from rich.console import Console

from deploy.launch.run_board import BoardView, ProcessView, render_board
from deploy.report.verdict import print_verdict, read_verdict

PROGRESS = {"max_estimator_error_m": 0.012, "max_abs_e_rho_m": 0.25, "max_abs_e_delta": 0.004,
            "links": {"count": 12, "silent": [], "min_delivered": 0.98,
                      "min_delivered_link": "f0->f1", "max_age_ms": 41.5,
                      "max_age_link": "f2->f3"}}


def view(n: int) -> BoardView:
    procs = [ProcessView("sim", "up", "running"), ProcessView("recorder", "up", "running")]
    procs += [ProcessView(f"follower-{i}", "up", "running") for i in range(n)]
    procs += [ProcessView(f"target-{j}", "up", "running") for j in range(2)]
    return BoardView("enclose run bench", 20.0, 10.0, 24.0, {"rho": 0.0999, "delta": 0.0199},
                     PROGRESS, tuple(procs), ("5.0 s follower-1 died signal=SIGKILL",))


def median_ms(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1e3 * statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=200)
    parser.add_argument("--run-dir", type=Path, default=None, help="a finished run's directory")
    args = parser.parse_args()
    console = Console(file=io.StringIO(), width=120, force_terminal=True)
    for n in (4, 16):
        v = view(n)
        ms = median_ms(lambda v=v: console.print(render_board(v)), args.repeat)
        print(f"board, {n:2d} followers: {ms:.2f} ms per redraw (median of {args.repeat})")
    if args.run_dir is not None:
        run_dir = args.run_dir
        ms = median_ms(lambda: print_verdict(console, read_verdict(run_dir, "bench")),
                       args.repeat)
        print(f"verdict of {run_dir}: {ms:.2f} ms (read + print)")


if __name__ == "__main__":
    main()
