"""Cost of the followers' input journal (agents.follower.journal) and replay speed.

Runs `enclose run SCENARIO --duration D` (or takes a finished run: --run-dir) and, per
follower: the journal's size per minute of flight, the CPU of writing it (its records
written again through `JournalWriter`, compression and flushes included, timed by
thread CPU) as a share of a core and of the follower's own CPU in that run, and how fast
`enclose replay` re-runs it (steps per second).  On a loaded machine the follower's CPU
share is inflated and the shares are only indicative: the output says the machine's load.

Run: python -m bench.bench_journal --scenario ring16 --duration 20
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from agents.follower.journal import (
    JOIN,
    REGROUP,
    STEP,
    JournalWriter,
    Mirror,
    PeerCodec,
    read_sample,
    read_target,
)
from agents.follower.journal_file import Frames
from agents.follower.journal_replay import replay
from agents.loading.law_loader import make_law
from deploy.commands.replay import run_scenario
from transport.law_fields import FieldSpec


def rewrite_cpu_s(path: Path) -> tuple[float, int, float]:
    """CPU seconds to write `path`'s records again, its step count, its span (s)."""
    frames = Frames.open(path)
    records = [r for _, r in frames.records()]
    codec = PeerCodec(frames.header.get("fields") or [])
    targets, peers, joins = Mirror(read_target), Mirror(codec.decode), Mirror(codec.decode)
    calls: list[tuple[str, Any]] = []
    for rec in records:  # decoded first: only the writing is timed
        if rec[0] == STEP:
            own, res = read_sample(rec[3]), None
            calls.append((STEP, (rec[1], rec[2], own, targets.apply(rec[4]),
                                 peers.apply(rec[5]), res, rec[6])))
        elif rec[0] == REGROUP:
            calls.append((REGROUP, tuple(rec[1])))
        elif rec[0] == JOIN:
            calls.append((JOIN, (joins.apply(rec[2]), rec[1])))
    steps = [c for k, c in calls if k == STEP]
    span_s = steps[-1][0] - steps[0][0] if len(steps) > 1 else 0.0
    with tempfile.TemporaryDirectory() as tmp:
        header = {k: v for k, v in frames.header.items() if k != "fields"}
        writer = JournalWriter(Path(tmp) / "j", header, {
            name: FieldSpec(name, "vec2", 1.0, rate=rate) for name, rate in codec.fields})
        writer.file._next_flush_s = float("inf")  # flushed below, once a simulated second
        per_s = max(1, round(len(steps) / span_s)) if span_s > 0 else 50
        t0 = time.thread_time()
        for n, (kind, c) in enumerate(calls):
            if kind == STEP:
                writer.step(*c[:5], _Result.of(c[6]))
            elif kind == REGROUP:
                writer.regroup(c)
            else:
                writer.join(*c)
            if n % per_s == 0:
                writer.file.flush()
        writer.close()
        return time.thread_time() - t0, len(steps), span_s


class _Result:
    """A step's result as the writer takes it (its CRCs cost the same whatever the values)."""

    @staticmethod
    def of(done: list[Any] | None) -> Any:
        if done is None:
            return None
        from agents.law.interface import Output

        fields = {"link_sums_m": ((1, 0.5, 0.25), (3, 0.5, 0.25))}
        return Output(1j, 2j, 3j, {}), fields


def measure(run_dir: Path) -> None:
    load = json.loads((run_dir / "launch.json").read_text()).get("load", {})
    cpu = load.get("process_cpu_pct", {})
    print(f"machine: {load.get('cores')} cores, {load.get('machine_busy_pct')} % busy, "
          f"load {load.get('load_1min')} (shared: shares below are indicative)")
    for path in sorted((run_dir / "journal").glob("follower-*.journal"),
                       key=lambda p: int(p.stem.split("-")[1])):
        name = path.stem
        cpu_s, steps, span_s = rewrite_cpu_s(path)
        mb_min = path.stat().st_size / 1e6 / (span_s / 60.0) if span_s else float("nan")
        core_pct = 100.0 * cpu_s / span_s if span_s else float("nan")
        own = cpu.get(name)
        share = f"{100.0 * core_pct / own:.1f} % of its CPU ({own} % of a core)" if own else "?"
        t0 = time.perf_counter()
        scenario = run_scenario(Frames.open(path).header)
        found = replay(path, scenario, make_law(scenario))
        rate = found.steps / (time.perf_counter() - t0)
        print(f"{name}: {steps} steps over {span_s:.1f} s, {mb_min:.2f} MB/min, writing "
              f"{core_pct:.2f} % of a core = {share}; replay {rate:.0f} steps/s, "
              f"{'reproduced' if found.reproduced else 'NOT reproduced'}")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--scenario", default="paper")
    p.add_argument("--duration", type=float, default=20.0)
    p.add_argument("--run-dir", type=Path, default=None, help="a finished run to measure")
    args = p.parse_args()
    run_dir = args.run_dir
    if run_dir is None:
        run_dir = Path(tempfile.mkdtemp(prefix="bench-journal-"))
        argv = [sys.executable, "-m", "deploy.cli", "run", args.scenario, "--out",
                str(run_dir), "--duration", str(args.duration), "--link-timeout", "120"]
        subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, timeout=600)
    measure(run_dir)
    return 0


if __name__ == "__main__":
    sys.exit(main())
