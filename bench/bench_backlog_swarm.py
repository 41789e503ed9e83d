"""A real swarm's recorder put behind: its RSS before, at the peak and after it caught up
(issue "Hours, not minutes": a backlog's memory, where it happens: ring64 on 2 cores).

Runs `enclose run CASE --duration DURATION --no-live --no-figures`.  `--at-s` seconds into
the experiment (after the start word) the recorder is put behind for `--stall-s` seconds,
either
- `starve` (default): all its threads in a CPU cgroup of `--quota-pct` % of one core, as
  when a saturated machine leaves it too little; Zenoh's thread keeps receiving, a message
  or two per read, so this is the backlog a soak shows; or
- `stop`: SIGSTOP, then SIGCONT (everything it missed arrives at once, in large reads).
Printed per run: the recorder's largest RSS over the 5 s before, its peak after, its mean
over the run's last 10 s, the backlog's own peak and what it lost (metrics.json), and the
run's errors.  `starve` needs root and a cgroup CPU controller (v1 or v2).

Run: python bench/bench_backlog_swarm.py [--case ring64] [--runs 3] [--how starve|stop]
     [--stall-s 25] [--out /tmp/backlog-swarm]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from deploy.procs.pids import read_pids
from deploy.report.cpu_load import process_status_kb

CGROUP_V1, CGROUP_V2 = Path("/sys/fs/cgroup/cpu"), Path("/sys/fs/cgroup")


class Starver:
    """A CPU cgroup of `quota_pct` % of one core; moves a process's threads in and out."""

    def __init__(self, quota_pct: float) -> None:
        period_us, quota_us = 100_000, int(1000 * quota_pct)
        if (CGROUP_V2 / "cgroup.controllers").exists():
            self.root, self.tasks = CGROUP_V2, "cgroup.threads"
            self.group = CGROUP_V2 / f"enclose-starve-{os.getpid()}"
            self.group.mkdir()
            (self.group / "cpu.max").write_text(f"{quota_us} {period_us}")
        elif CGROUP_V1.is_dir():
            self.root, self.tasks = CGROUP_V1, "tasks"
            self.group = CGROUP_V1 / f"enclose-starve-{os.getpid()}"
            self.group.mkdir()
            (self.group / "cpu.cfs_quota_us").write_text(str(quota_us))
        else:
            raise SystemExit("no cgroup CPU controller here: use --how stop")

    def move(self, pid: int, into: bool) -> None:
        target = (self.group if into else self.root) / self.tasks
        for tid in os.listdir(f"/proc/{pid}/task"):
            with contextlib.suppress(OSError):  # a thread that ended meanwhile
                target.write_text(tid)

    def remove(self) -> None:
        self.group.rmdir()


def _running(out: Path) -> bool:
    try:
        return json.loads((out / "progress.json").read_text()).get("state") == "running"
    except (OSError, ValueError):
        return False


def one_run(args: argparse.Namespace, out: Path) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "deploy.cli", "run", args.case, "--duration",
           str(args.duration_s), "--no-live", "--no-figures", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            cwd=Path(__file__).resolve().parents[1])
    starver = Starver(args.quota_pct) if args.how == "starve" else None
    put_behind: Callable[[int, bool], None] = (
        (lambda pid, on: starver.move(pid, on)) if starver is not None else
        (lambda pid, on: os.kill(pid, signal.SIGSTOP if on else signal.SIGCONT)))
    samples: list[tuple[float, float]] = []
    try:
        samples = _watch(proc, out, args, put_behind)
    finally:
        if proc.poll() is None:
            proc.wait(timeout=args.duration_s + 120)
        if starver is not None:
            starver.remove()
    return _summary(out, samples, args)


def _watch(proc: subprocess.Popen[bytes], out: Path, args: argparse.Namespace,
           put_behind: Callable[[int, bool], None]) -> list[tuple[float, float]]:
    """RSS every 0.5 s from the start word on; the stall at its times."""
    pid, t0, state = None, None, "before"
    samples: list[tuple[float, float]] = []
    maps: dict[str, dict[str, int]] = {}
    while proc.poll() is None:
        time.sleep(0.5)
        if pid is None:
            recorder = read_pids(out / "logs").get("recorder")
            pid = recorder.pid if recorder is not None else None
        if pid is None or (t0 is None and not _running(out)):
            continue
        t0 = t0 or time.monotonic()
        t = time.monotonic() - t0
        if state == "before" and t >= args.at_s:
            put_behind(pid, True)
            state = "behind"
        elif state == "behind" and t >= args.at_s + args.stall_s:
            put_behind(pid, False)
            state = "after"
        rss_kb = process_status_kb(pid, "VmRSS")
        if rss_kb is not None and t < args.duration_s:
            samples.append((t, rss_kb / 1024))
        # Read smaps only in the seconds each snapshot needs: it walks the recorder's pages.
        if args.maps and state == "before" and t >= args.at_s - 2:
            maps["before"] = resident_by_mapping(pid)
        elif args.maps and args.duration_s - 3 <= t < args.duration_s - 1:
            maps["end"] = resident_by_mapping(pid)
    if args.maps and len(maps) == 2:
        _print_map_change(maps["before"], maps["end"])
    return samples


def resident_by_mapping(pid: int) -> dict[str, int]:
    """Resident kB of each mapping of `pid` (/proc/<pid>/smaps), by "start-end name"."""
    rss: dict[str, int] = {}
    name = ""
    with contextlib.suppress(OSError), open(f"/proc/{pid}/smaps") as f:
        for line in f:
            head = line.split()
            if "-" in head[0] and not head[0].endswith(":"):
                name = f"{head[0]} {head[5] if len(head) > 5 else '[anon]'}"
            elif head[0] == "Rss:":
                rss[name] = int(head[1])
    return rss


def _print_map_change(before: dict[str, int], end: dict[str, int]) -> None:
    """The mappings whose resident memory moved by 256 kB or more, and the totals."""
    for name in sorted(set(before) | set(end)):
        d = end.get(name, 0) - before.get(name, 0)
        if abs(d) >= 256:
            first, last = name.split()[0].split("-")
            size_kb = (int(last, 16) - int(first, 16)) // 1024
            print(f"  {name} ({size_kb} kB): {before.get(name, 0)} -> {end.get(name, 0)} kB",
                  flush=True)
    print(f"  total resident {sum(before.values())} -> {sum(end.values())} kB", flush=True)


def _summary(out: Path, samples: list[tuple[float, float]],
             args: argparse.Namespace) -> dict[str, Any]:
    metrics = json.loads((out / "metrics.json").read_text())
    at, end = args.at_s, args.duration_s
    before = max(mb for t, mb in samples if at - 5 <= t < at)
    tail = [mb for t, mb in samples if t >= end - 10]
    return {"before_mb": before, "peak_mb": max(mb for t, mb in samples if t >= at),
            "end_mb": sum(tail) / len(tail),
            "deferred": metrics["recorder"].get("deferred"),
            "errors": {k: metrics.get(k) for k in ("estimator_error_m", "radius_error_m",
                                                   "angle_error")}}


def main(args: argparse.Namespace) -> None:
    for k in range(args.runs):
        s = one_run(args, args.out / f"run{k}")
        print(f"run {k}: before {s['before_mb']:.1f} MB, peak {s['peak_mb']:.1f} MB "
              f"(+{s['peak_mb'] - s['before_mb']:.1f}), end {s['end_mb']:.1f} MB "
              f"(+{s['end_mb'] - s['before_mb']:.1f}); deferred {s['deferred']}; "
              f"errors {s['errors']}", flush=True)


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="ring64")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--how", choices=("starve", "stop"), default="starve")
    parser.add_argument("--at-s", type=float, default=40.0)
    parser.add_argument("--stall-s", type=float, default=25.0)
    parser.add_argument("--quota-pct", type=float, default=10.0)
    parser.add_argument("--duration-s", type=float, default=110.0)
    parser.add_argument("--out", type=Path, default=Path("/tmp/backlog-swarm"))
    parser.add_argument("--maps", action="store_true",
                        help="print the recorder's mappings whose resident memory moved "
                        "between the stall's start and the run's end (/proc/<pid>/smaps)")
    args = parser.parse_args()
    if args.at_s + args.stall_s + 15 > args.duration_s:
        parser.error("--at-s + --stall-s must end at least 15 s before --duration-s")
    return args


if __name__ == "__main__":
    main(parse_args())
