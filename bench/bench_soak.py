"""A long run, watched: every process's memory and CPU over time, late ticks and errors per
window (issue "Hours, not minutes").

Runs `enclose run CASE --duration MINUTES*60` and, each `--sample-s` (default 60 s), reads
every child's VmRSS and CPU time (/proc; the PIDs of logs/pids.json, plus the launcher's
own).  At the end:
- per process (and per role: followers, targets...): RSS at the first sample after
  `--settle-min` (default 5 min), at the last sample of the flight, the growth between
  them in %, and the least-squares slope over those samples in MB per hour; mean CPU in %
  of one core; the peak (VmHWM; the recorder's includes writing the outputs); the
  machine's 1-minute load average over the same samples (other work on the machine);
  and the ceiling's growth: the highest RSS after the settling against the highest
  before it, which stays near 0 for memory that swings under a bound (a recorder that
  hands a worked-off backlog back) and grows with a leak as the point growth does;
- per window of `--window-min` of experiment time: the followers' late ticks (their
  `overruns` / `ticks` counters from the statuses in recording.mcap) and the simulator's,
  and the worst errors (|e_rho|, |e_delta|, |r - LAP| from series.parquet), with their
  95th percentile (a transient moves the worst alone);
- whether the last window is no worse than the first steady one (the first window that
  starts after `--settle-min`): late-tick rate at most its double plus 0.1 % of ticks,
  each error at most 1.25 times its value or inside the paper's bound;
- how long the recorder took to write the end-of-run outputs, and from its stop to its
  done (its log says); what it decoded late, in batches, and what it dropped.
The raw samples go to OUT/soak.json; `--report-only` reports a finished run from it again.

Run: python bench/bench_soak.py [--case paper] [--minutes 10] [--window-min 2]
     [--out runs/soak-paper] [--insecure] [--report-only] [-- MORE ENCLOSE RUN OPTIONS]
"""

from __future__ import annotations

import argparse
import json
import math
import re
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from soak_memory import load_range, memory_table, role_table
from soak_windows import (
    ERROR_COLUMNS,
    errors_over,
    late_ok,
    late_over,
    late_per_minute,
    verdict,
    worst_errors,
)

from deploy.procs.pids import read_pids
from deploy.report.cpu_load import load_1min, process_cpu_s, process_status_kb

_OUTPUTS = re.compile(r"run outputs written in ([0-9.]+) s")
_STATE = re.compile(r"^(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3}) .*recorder (stopping|done|failed)$",
                    re.MULTILINE)


def flying(out: Path) -> bool:
    """True until the flight's end: the recorder has not stopped and its last truth is
    before the planned end (after it come the stop and the end-of-run outputs)."""
    try:
        progress = json.loads((out / "progress.json").read_text())
    except (OSError, ValueError):
        return True
    t_s, duration_s = progress.get("t_s"), progress.get("duration_s")
    early = t_s is None or duration_s is None or t_s < duration_s - 2.0
    return progress.get("state", "") in ("starting", "linked", "running") and early


def sample(out: Path, launcher_pid: int, t_s: float) -> list[dict[str, Any]]:
    """One reading of every process: name, pid, RSS and HWM (MB), CPU seconds."""
    rows = []
    pids = {name: ident.pid for name, ident in read_pids(out / "logs").items()}
    load = load_1min()
    for name, pid in {"launcher": launcher_pid, **pids}.items():
        rss, hwm, cpu = (process_status_kb(pid, "VmRSS"), process_status_kb(pid, "VmHWM"),
                         process_cpu_s(pid))
        if rss is None or hwm is None or cpu is None:
            continue
        anon = process_status_kb(pid, "RssAnon")  # the heaps, without mapped files
        rows.append({"t_s": round(t_s, 2), "name": name, "pid": pid, "rss_mb": rss / 1024,
                     "anon_mb": None if anon is None else anon / 1024, "hwm_mb": hwm / 1024,
                     "cpu_s": cpu, "load_1min": load})
    return rows


def watch(proc: subprocess.Popen[bytes], out: Path, period_s: float) -> list[dict[str, Any]]:
    """Samples each period while the recorder runs, then each second until the end (the
    peak of writing the outputs)."""
    t0, samples, next_s = time.monotonic(), [], 0.0
    while proc.poll() is None:
        now = time.monotonic() - t0
        in_flight = flying(out)
        if now >= next_s or not in_flight:
            for row in sample(out, proc.pid, now):
                samples.append({**row, "flying": in_flight})
            next_s = now + period_s
            (out / "soak.json").write_text(json.dumps({"samples": samples}) + "\n")
        time.sleep(1.0)
    return samples


def outputs_s(out: Path) -> float | None:
    found = []
    for log in sorted((out / "logs").glob("recorder*.log")):
        found += _OUTPUTS.findall(log.read_text(errors="replace"))
    return float(found[-1]) if found else None


def stop_to_done_s(out: Path) -> float | None:
    """From the recorder's "stopping" to its "done" (its log's stamps): the whole end of
    the run, closing the MCAP and importing the figures' libraries included."""
    log = out / "logs" / "recorder.log"
    text = log.read_text(errors="replace") if log.exists() else ""
    stamps = {state: datetime.strptime(at, "%Y-%m-%d %H:%M:%S,%f")
              for at, state in _STATE.findall(text)}
    end = stamps.get("done") or stamps.get("failed")
    if "stopping" not in stamps or end is None:
        return None
    return round((end - stamps["stopping"]).total_seconds(), 2)


def report(out: Path, args: argparse.Namespace, samples: list[dict[str, Any]]) -> dict[str, Any]:
    metrics = json.loads((out / "metrics.json").read_text())
    info = json.loads((out / "run.json").read_text())
    settle_s = 60 * args.settle_min
    memory = memory_table(samples, settle_s)
    summary: dict[str, Any] = {
        "case": args.case, "minutes": args.minutes, "window_min": args.window_min,
        "settle_min": args.settle_min, "memory": memory, "roles": role_table(memory),
        "load_1min": load_range(samples, settle_s),
        "outputs_s": outputs_s(out), "stop_to_done_s": stop_to_done_s(out),
        # The states and observations it decoded late, in batches (deploy.recording.intake).
        "recorder_deferred": metrics.get("recorder", {}).get("deferred"),
        "metrics": {k: metrics.get(k) for k in ("estimator_error_m", "radius_error_m",
                                                "angle_error", "settle_time_s", "samples")},
    }
    summary.update(compare(out, args, metrics["start_stamp_s"], {
        "e_rho_m": info["eps_rho_m"], "e_delta": info["eps_delta"],
        "est_err_m": info["eps_rho_m"]}))
    return summary


def compare(out: Path, args: argparse.Namespace, start_stamp_s: float,
            bounds: dict[str, float]) -> dict[str, Any]:
    """Late ticks and errors per window, and two comparisons of the last against the first
    steady stretch: the window after the settling against the last window, and (as the
    issue puts it) the first steady `--compare-min` minutes against the last ones."""
    late_min = late_per_minute(out, start_stamp_s)
    t_s, worst = worst_errors(out)
    w = args.window_min
    windows = [(k * w, (k + 1) * w) for k in range(math.ceil(args.minutes / w - 1e-9))]
    per_window = [errors_over(t_s, worst, span) for span in windows]
    first_w, last_w = math.ceil(args.settle_min / w - 1e-9), len(windows) - 1
    spans = [(args.settle_min, args.settle_min + args.compare_min),
             (args.minutes - args.compare_min, args.minutes)]
    per_span = [errors_over(t_s, worst, span) for span in spans]
    found: dict[str, Any] = {
        "late_ticks": {role: [late_over(m, span) for span in windows]
                       for role, m in late_min.items()},
        "errors": [e[0] for e in per_window], "errors_p95": [e[1] for e in per_window],
        "windows_compared": [first_w, last_w], "spans_compared": spans,
        "span_late_ticks": {role: [late_over(m, span) for span in spans]
                            for role, m in late_min.items()},
        "span_errors": [e[0] for e in per_span], "span_errors_p95": [e[1] for e in per_span]}
    # A verdict only where both stretches hold data: an empty one would read "no worse".
    if 0 <= first_w < last_w:
        rows = found["late_ticks"].get("follower") or [[0, 0]] * len(windows)
        fol = [rows[first_w], rows[last_w]]
        _judge(found, "", (per_window[first_w][0], per_window[last_w][0]), fol, bounds)
    if spans[0][1] <= args.minutes:
        fol = found["span_late_ticks"].get("follower", [[0, 0], [0, 0]])
        _judge(found, "span_", (per_span[0][0], per_span[1][0]), fol, bounds)
    return found


def _judge(found: dict[str, Any], prefix: str, errors: tuple[dict[str, float], dict[str, float]],
           late: list[list[int]], bounds: dict[str, float]) -> None:
    if errors[0] and errors[1]:
        found[f"{prefix}errors_no_worse"] = verdict(errors[0], errors[1], bounds)
    if late[0][1] and late[1][1]:
        found[f"{prefix}late_no_worse"] = late_ok(late[0], late[1])


def show(summary: dict[str, Any]) -> None:
    print(f"soak {summary['case']}, {summary['minutes']:g} min "
          f"(windows of {summary['window_min']:g} min)")
    settled = f"RSS@{summary.get('settle_min', 5):g}min"  # older soak.json: 5
    print(f"{'process':<14}{settled:>10}{'RSS end':>10}{'growth':>9}{'MB/h':>9}"
          f"{'CPU %':>8}{'peak':>8}{'ceiling':>9}")
    for r in summary["memory"]:
        if "rss_start_mb" not in r:
            continue
        print(f"{r['name']:<14}{r['rss_start_mb']:>10.1f}{r['rss_end_mb']:>10.1f}"
              f"{r['growth_pct']:>8.2f}%{_fmt(r['slope_mb_h']):>9}{r['cpu_pct']:>8.1f}"
              f"{r['peak_mb']:>8.1f}{_fmt(r.get('ceiling_growth_pct')):>8}%")
    for g in summary["roles"]:
        print(f"{g['role']} ({g['processes']}): RSS {_span(g['rss_start_mb'])} -> "
              f"{_span(g['rss_end_mb'])} MB, growth at most {g['growth_pct_max']:+.2f} %, "
              f"slope at most {_fmt(g['slope_mb_h_max'])} MB/h, peak {g['peak_mb_max']:.1f} MB, "
              f"ceiling growth at most {_fmt(g.get('ceiling_growth_pct_max'))} %")
    print(f"machine load (1-min average) after the settling: {summary['load_1min']}")
    for role, rows in summary["late_ticks"].items():
        cells = " ".join(f"{late}/{ticks}" for late, ticks in rows)
        print(f"late ticks per window, {role}: {cells}")
    for kind in ERROR_COLUMNS:
        cells = " ".join(f"{w.get(kind, math.nan):.4g}" for w in summary["errors"])
        print(f"max |{kind}| per window: {cells}")
        cells = " ".join(f"{w.get(kind, math.nan):.4g}" for w in summary.get("errors_p95", []))
        print(f"p95 |{kind}| per window: {cells}")
    first, last = summary["windows_compared"]
    print(f"window {last} against window {first}: errors no worse "
          f"{summary.get('errors_no_worse')}, late ticks no worse {summary.get('late_no_worse')}")
    (a0, a1), (b0, b1) = summary["spans_compared"]
    pairs = zip(summary["span_errors"], summary["span_errors_p95"], strict=True)
    for k, (peak, p95) in enumerate(pairs):
        cells = ", ".join(f"{kind} {peak.get(kind, math.nan):.4g} "
                          f"(p95 {p95.get(kind, math.nan):.4g})" for kind in ERROR_COLUMNS)
        late = {role: v[k] for role, v in summary["span_late_ticks"].items()}
        print(f"minutes {(a0, b0)[k]:g}-{(a1, b1)[k]:g}: max {cells}; late ticks {late}")
    print(f"minutes {b0:g}-{b1:g} against minutes {a0:g}-{a1:g}: errors no worse "
          f"{summary.get('span_errors_no_worse')}, late ticks no worse "
          f"{summary.get('span_late_no_worse')}")
    print(f"end-of-run outputs written in {summary['outputs_s']} s "
          f"({summary['stop_to_done_s']} s from the recorder's stop to done); "
          f"metrics {summary['metrics']}")
    print(f"recorder deferred decoding: {summary.get('recorder_deferred')}")


def _span(v: list[float]) -> str:
    return f"{v[0]:.1f}" if v[0] == v[1] else f"{v[0]:.1f}-{v[1]:.1f}"


def _fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:+.2f}"


def main() -> None:
    args = parse_args()
    out = (args.out or Path(f"runs/soak-{args.case}")).resolve()
    if args.report_only:  # the figures again from a finished run's soak.json
        samples = json.loads((out / "soak.json").read_text())["samples"]
    else:
        samples = fly(args, out)
    summary = report(out, args, samples)
    (out / "soak.json").write_text(json.dumps({"summary": summary, "samples": samples}) + "\n")
    show(summary)


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--case", default="paper")
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--sample-s", type=float, default=60.0)
    parser.add_argument("--window-min", type=float, default=None,
                        help="window of late ticks and errors (default: 10 min from 40-min "
                        "runs, else a fifth of the run)")
    parser.add_argument("--settle-min", type=float, default=5.0)
    parser.add_argument("--compare-min", type=float, default=10.0,
                        help="the last this many minutes against the first this many after "
                        "the settling (default 10, as issue 'Hours, not minutes' asks)")
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--insecure", action="store_true")
    parser.add_argument("--report-only", action="store_true",
                        help="no run: the report of the run already in --out (same --case "
                        "and --minutes)")
    parser.add_argument("run_args", nargs="*", help="more `enclose run` options, after --")
    args = parser.parse_args()
    if args.window_min is None:
        args.window_min = 10.0 if args.minutes >= 40 else args.minutes / 5
    return args


def fly(args: argparse.Namespace, out: Path) -> list[dict[str, Any]]:
    argv = [sys.executable, "-m", "deploy.cli", "run", args.case, "--duration",
            str(60 * args.minutes), "--out", str(out), *(["--insecure"] if args.insecure else []),
            *args.run_args]
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "launcher.out", "wb") as log:
        proc = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT)
        try:
            return watch(proc, out, args.sample_s)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()


if __name__ == "__main__":
    main()
