"""What a tick costs, phase by phase, over all of a process's threads (issue 50).

    python bench/bench_tick_cost.py [--case paper] [--duration 60] [--repeat 5] [--insecure]
                                    [--floor] [ENCLOSE_RUN_ARG ...]

Runs `enclose run CASE` (the secure default unless --insecure; any other argument is passed
on, e.g. `--zenoh-runtime one_thread`, for an A/B) with ENCLOSE_TICK_COST set:
every follower and target then measures, from the start word to its last status, the CPU
of its loop thread per phase (agents.shell.tick_cost.PHASES) and of its threads by group (the
loop's, Zenoh's runtime, the rest), and reports them in its status.  Printed per tick, in
microseconds: each phase, `rest` (the loop thread's CPU outside the marks: signal
handlers, the garbage collector's pauses between marks land inside them), Zenoh's threads,
other threads, and the total over all threads, with the median follower of each run, then
the median and spread (min-max) over runs.  The simulator's CPU per vehicle-tick and the
recorder's per message recorded come from the run's own load record (launch.json: whole
run, start-up included).  With --floor, a run of bench/bench_floor.py at the case's size
and rate follows each run (the design's traffic alone), and the tick above it is printed:
each run's total minus its floor: enclose's own work.  Nothing else should run meanwhile:
say so where it did.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from agents.loading.scenario_file import load_scenario  # noqa: E402
from agents.shell.tick_cost import ENV, PHASES  # noqa: E402
from bench.bench_floor import floor_args, one_run  # noqa: E402

GROUPS = ("main", "zenoh", "other")
ROWS = (*PHASES, "rest", "thread_zenoh", "thread_other", "total")


def per_tick(counters: dict[str, int]) -> dict[str, float] | None:
    """µs per tick of one process's cost counters; None without them."""
    ticks = counters.get("cost_ticks", 0)
    if ticks <= 0:
        return None
    row = {p: counters.get(f"cost_us_{p}", 0) / ticks for p in PHASES}
    main = counters.get("cost_us_thread_main", 0) / ticks
    row["rest"] = max(main - sum(row[p] for p in PHASES), 0.0)
    row["thread_zenoh"] = counters.get("cost_us_thread_zenoh", 0) / ticks
    row["thread_other"] = counters.get("cost_us_thread_other", 0) / ticks
    row["total"] = main + row["thread_zenoh"] + row["thread_other"]
    return row


def median_row(rows: list[dict[str, float]]) -> dict[str, float]:
    return {k: statistics.median(r[k] for r in rows) for k in ROWS}


def run_once(case: str, duration_s: float, insecure: bool, out: Path,
             extra: list[str]) -> dict[str, object]:
    cmd = [str(ROOT / ".venv" / "bin" / "enclose"), "run", case, "--duration", str(duration_s),
           "--no-live", "--no-figures", "--out", str(out), *extra]
    if insecure:
        cmd.append("--insecure")
    env = {**os.environ, ENV: "1"}
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    launch = json.loads((out / "launch.json").read_text())
    status = launch["status_at_stop"]
    followers = [r for name, s in status.items() if name.startswith("follower-")
                 if (r := per_tick(s)) is not None]
    targets = [r for name, s in status.items() if name.startswith("target-")
               if (r := per_tick(s)) is not None]
    load = launch["load"]
    verdict = proc.stdout.splitlines()[0] if proc.stdout else proc.stderr[-300:]
    return {"followers": followers, "targets": targets, "load": load, "verdict": verdict,
            "status": status, "launch": launch}


def sim_and_recorder(result: dict[str, object], duration_s: float) -> tuple[float, float]:
    """(simulator µs per vehicle-tick, recorder µs per message), whole run."""
    load: dict = result["load"]  # type: ignore[assignment]
    status: dict = result["status"]  # type: ignore[assignment]
    launch: dict = result["launch"]  # type: ignore[assignment]
    wall_s = duration_s + float(launch.get("link_s") or 0.0)
    cpu = load["process_cpu_pct"]
    sim = status.get("sim-0", {})
    vehicles = sum(1 for n in status if n.startswith(("follower-", "target-")))
    sim_us = cpu.get("sim", 0.0) / 100 * wall_s * 1e6 / max(sim.get("ticks", 1) * vehicles, 1)
    rec = status.get("recorder-0", {})
    rec_us = cpu.get("recorder", 0.0) / 100 * wall_s * 1e6 / max(rec.get("mcap_messages", 1), 1)
    return sim_us, rec_us


def show(label: str, rows: list[dict[str, float]]) -> None:
    print(f"{label} (us per tick; median over runs [min-max])")
    for k in ROWS:
        vals = [r[k] for r in rows]
        print(f"  {k:14s} {statistics.median(vals):8.1f}  [{min(vals):7.1f} - {max(vals):7.1f}]")


def floor_settings(case: str, insecure: bool, extra: list[str]) -> argparse.Namespace:
    """A floor run (bench/bench_floor.py) at `case`'s size, rate and Zenoh runtime: a
    follower's traffic alone, measured as its CPU per tick over all its threads."""
    scenario = load_scenario(case)
    runtime = scenario.network.zenoh_runtime
    if "--zenoh-runtime" in extra[:-1]:
        runtime = extra[extra.index("--zenoh-runtime") + 1]
    return floor_args(scenario.n, scenario.run.rate_hz, insecure, runtime)


def main(case: str, duration_s: float, repeat: int, insecure: bool,
         extra: list[str], floor: bool = False) -> int:
    per_run: list[dict[str, float]] = []
    per_run_targets: list[dict[str, float]] = []
    sims, recs, busy, floors = [], [], [], []
    floor_run = floor_settings(case, insecure, extra) if floor else None
    with tempfile.TemporaryDirectory(prefix="tick-cost-") as tmp:
        for k in range(repeat):
            res = run_once(case, duration_s, insecure, Path(tmp) / f"run-{k}", extra)
            followers: list = res["followers"]  # type: ignore[assignment]
            if not followers:
                print(f"run {k + 1}: no cost counters: {res['verdict']}", file=sys.stderr)
                return 1
            per_run.append(median_row(followers))
            targets: list = res["targets"]  # type: ignore[assignment]
            if targets:
                per_run_targets.append(median_row(targets))
            sim_us, rec_us = sim_and_recorder(res, duration_s)
            sims.append(sim_us)
            recs.append(rec_us)
            load: dict = res["load"]  # type: ignore[assignment]
            busy.append(load["machine_busy_pct"])
            print(f"run {k + 1}/{repeat}: follower {per_run[-1]['total']:.0f} us/tick, "
                  f"machine {load['machine_busy_pct']:.0f} % busy; {res['verdict']}",
                  flush=True)
            if floor_run is not None:  # alternated with the real runs: the minute moves both
                floors.append(one_run(floor_run, floor_run.port + 100 * k)["follower_us"])
                print(f"  floor after it: {floors[-1]:.0f} us/tick", flush=True)
    mode = "--insecure" if insecure else "secure"
    print(f"\n{case} {' '.join(extra)}, {duration_s:g} s, {repeat} runs, {mode}; machine busy "
          f"{min(busy):.0f}-{max(busy):.0f} %")
    show("follower (median follower of each run)", per_run)
    if floors:
        above = [r["total"] - f for r, f in zip(per_run, floors, strict=True)]
        print(f"floor      {statistics.median(floors):.0f} us per tick [{min(floors):.0f} - "
              f"{max(floors):.0f}] (bench/bench_floor.py: the traffic alone, a run after each)")
        print(f"above it   {statistics.median(above):.0f} us per tick [{min(above):.0f} - "
              f"{max(above):.0f}] (enclose's own work: each run's total minus its floor)")
    if per_run_targets:
        show("target", per_run_targets)
    print(f"simulator  {statistics.median(sims):.1f} us per vehicle-tick "
          f"[{min(sims):.1f} - {max(sims):.1f}] (whole run)")
    print(f"recorder   {statistics.median(recs):.1f} us per message recorded "
          f"[{min(recs):.1f} - {max(recs):.1f}] (whole run)")
    return 0


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--case", default="paper")
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--insecure", action="store_true")
    parser.add_argument("--floor", action="store_true",
                        help="after each run, the design's floor at the case's size and rate "
                             "(bench/bench_floor.py), and the tick above it")
    a, passed_on = parser.parse_known_args()
    sys.exit(main(a.case, a.duration, a.repeat, a.insecure, passed_on, a.floor))
