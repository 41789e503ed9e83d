"""Time to re-form after membership changes, on real runs (issue 10).

Each case is one `enclose run` with scripted faults; the recorder's metrics.json gives,
per membership phase, the time the re-formed ring took to enter the paper's bounds
(|e_rho| < 0.0999 m and |e_delta| < 0.0199 for every member, to the end of the phase).
Cases:
  leave     paper, follower 2 leaves cleanly at FAULT_AT
  join      paper, follower 2 leaves at FAULT_AT and joins again JOIN_AFTER later
  kill      paper, follower 1 SIGKILLed at FAULT_AT, restarted by the launcher
  sim       paper, the simulator restarts at FAULT_AT (vehicles reboot: take-off again)
  ring16x3  ring16, followers 2, 7 and 12 SIGKILLed at once, --restart never
  ring16x3r ring16, the same three SIGKILLed at once, restarted by the launcher (default)

Run: python bench/bench_membership.py [--cases leave,join] [--duration 100] [--at 30]
[--repeats 3] (each run takes its duration plus ~20 s of start-up).  With several repeats
the last table gives, per case and phase after the fault, the median re-form time and its
range over the runs (one run is not a result: re-forming depends on machine load).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

JOIN_AFTER_S = 15.0


def cases(at_s: float) -> dict[str, tuple[str, list[str]]]:
    a = f"{at_s:g}"
    kills = [x for j in (2, 7, 12) for x in ("--fault", f"{a}:kill:follower-{j}")]
    return {
        "leave": ("paper", ["--fault", f"{a}:leave:follower-2"]),
        "join": ("paper", ["--fault", f"{a}:leave:follower-2:{JOIN_AFTER_S:g}"]),
        "kill": ("paper", ["--fault", f"{a}:kill:follower-1"]),
        "sim": ("paper", ["--fault", f"{a}:restart:sim:1"]),
        "ring16x3": ("ring16", ["--restart", "never", *kills]),
        "ring16x3r": ("ring16", kills),
    }


def run_case(name: str, scenario: str, extra: list[str], duration_s: float,
             out_root: Path) -> dict[str, Any]:
    out = out_root / name
    argv = [sys.executable, "-m", "deploy.cli", "run", scenario, "--duration", f"{duration_s:g}",
            "--estimator", "robust", "--out", str(out), *extra]
    start = time.monotonic()
    code = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                          check=False).returncode
    metrics = json.loads((out / "metrics.json").read_text())
    launch = json.loads((out / "launch.json").read_text())
    return {"case": name, "exit": code, "wall_s": time.monotonic() - start,
            "phases": metrics.get("membership", {}).get("phases", []),
            "events": launch.get("events", [])}


def show(result: dict[str, Any]) -> None:
    print(f"\n{result['case']}: exit {result['exit']}, {result['wall_s']:.0f} s wall")
    for e in result["events"]:
        print(f"  event t={e['t_s']:7.2f} s  {e['process']:<12} {e['event']}")
    print(f"  {'from_s':>8} {'to_s':>8} {'members':<28} {'reform_s':>9} {'|r-LAP|':>8} "
          f"{'|e_rho|':>8} {'|e_delta|':>9}")
    for p in result["phases"]:
        if p["to_s"] - p["from_s"] < 0.5:
            continue  # the few ms in which members saw a change one after the other
        reform = p.get("reform_s")
        cells = [f"{p.get(k, float('nan')):8.4f}" for k in
                 ("estimator_error_m", "radius_error_m", "angle_error")]
        print(f"  {p['from_s']:8.2f} {p['to_s']:8.2f} {p['members']!s:<28} "
              f"{'never' if reform is None else f'{reform:.2f}':>9} {' '.join(cells)}")


def changed_phases(result: dict[str, Any]) -> list[dict[str, Any]]:
    """The phases after the first, skipping the ms-long ones while members saw a change."""
    return [p for p in result["phases"] if p["to_s"] - p["from_s"] >= 0.5][1:]


def summarise(results: dict[str, list[dict[str, Any]]]) -> None:
    print(f"\n{'case':<10} {'phase':>5} {'members':<28} {'runs':>4} {'never':>5} "
          f"{'median_s':>8} {'min_s':>6} {'max_s':>6}")
    for name, runs in results.items():
        by_phase: dict[int, list[float | None]] = {}
        members: dict[int, str] = {}
        for run in runs:
            for k, phase in enumerate(changed_phases(run)):
                by_phase.setdefault(k, []).append(phase.get("reform_s"))
                members.setdefault(k, str(phase["members"]))
        for k, values in sorted(by_phase.items()):
            done = [v for v in values if v is not None]
            stats = (f"{statistics.median(done):8.2f} {min(done):6.2f} {max(done):6.2f}"
                     if done else f"{'-':>8} {'-':>6} {'-':>6}")
            print(f"{name:<10} {k + 1:>5} {members[k]:<28} {len(values):>4} "
                  f"{len(values) - len(done):>5} {stats}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", default="leave,join,kill,sim,ring16x3")
    parser.add_argument("--duration", type=float, default=100.0)
    parser.add_argument("--at", type=float, default=30.0, help="experiment time of the faults")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("runs/bench-membership"))
    args = parser.parse_args()
    table = cases(args.at)
    results: dict[str, list[dict[str, Any]]] = {}
    for name in args.cases.split(","):
        scenario, extra = table[name]
        for k in range(args.repeats):
            result = run_case(name, scenario, extra, args.duration, args.out / f"{k}")
            show(result)
            results.setdefault(name, []).append(result)
    summarise(results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
