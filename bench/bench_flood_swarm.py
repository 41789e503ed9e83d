"""MAVLink flood on a real swarm: the paper's case (`enclose run`, signed), flooded at
follower 0's MAVLink port with badly signed datagrams from the start of the flight to 5 s
before its end; follower 0's late ticks, its refusals and the verdict, per level.

    python bench/bench_flood_swarm.py [--duration 40] [--repeat 2]

Late ticks: the Ticker's overruns of follower 0 over its ticks (launch.json's
status_at_stop, the verdict's definition), and the worst follower's.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from tests.integration.rogue import wait_running
from tests.integration.runs import spawned

AGENTS = re.compile(r"agents on UDP 127\.0\.0\.1:(\d+)")
# name, datagrams/s, bytes per datagram (6 MB/s but none)
LEVELS = (("none", 0, 0), ("100/s x 60 KB", 100, 60_000), ("5000/s x 1.2 KB", 5000, 1_200),
          ("20000/s x 300 B", 20_000, 300))


def one_run(dps: int, size: int, duration_s: float) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="bench-flood-swarm-") as tmp_dir:
        out = Path(tmp_dir) / "run"
        argv = [sys.executable, "-m", "deploy.cli", "run", "--out", str(out), "--no-live",
                "--duration", str(duration_s)]
        with spawned(argv, out) as launcher:
            assert launcher.stdout is not None
            lines = []
            for line in launcher.stdout:
                lines.append(line)
                if (m := AGENTS.search(line)) is not None:
                    break
            else:
                raise RuntimeError("".join(lines[-20:]))
            wait_running(out / "progress.json")
            flood_s = max(1.0, duration_s - 5.0)
            report = Path(tmp_dir) / "flood.json"
            subprocess.run([sys.executable, "-m", "tests.integration.mav_insider", "--seconds",
                            str(flood_s), "--out", str(report), "--flood-port", m.group(1),
                            "--flood-dps", str(dps), "--flood-size", str(max(1, size))],
                           check=True, timeout=flood_s + 60)
            tail, _ = launcher.communicate(timeout=duration_s + 120)
        if not (out / "metrics.json").exists():
            logs = "".join(f"--- {f.name}\n{f.read_text(errors='replace')[-2000:]}"
                           for f in sorted((out / "logs").glob("*.log")))
            raise RuntimeError(f"the run failed:\n{tail[-3000:]}\n{logs}")
        launch = json.loads((out / "launch.json").read_text())
        metrics = json.loads((out / "metrics.json").read_text())
        flood = json.loads(report.read_text())
    status = launch.get("status_at_stop") or launch["status"]
    late = {k: 100 * v.get("overruns", 0) / max(1, v.get("ticks", 1))
            for k, v in status.items() if k.startswith("follower-")}
    f0 = status["follower-0"]
    cpu = (launch.get("load") or {}).get("process_cpu_pct", {})
    return {"mb_s": flood["flood_bytes"] / flood_s / 1e6, "f0_late": late["follower-0"],
            "worst_late": max(late.values()), "f0_cpu": cpu.get("follower-0"),
            "refused": sum(v for k, v in f0.items() if k.startswith("signing_rejected_")),
            "kernel_drops": f0.get("mav_kernel_drops", 0),
            "inside": all(metrics.get(k, 1.0) < b for k, b in
                          (("estimator_error_m", 0.0999), ("radius_error_m", 0.0999),
                           ("angle_error", 0.0199))),
            "radius_error_m": metrics.get("radius_error_m")}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--duration", type=float, default=40.0)
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--only", nargs="*", default=None)
    args = p.parse_args()
    print("| flood at follower-0 | MB/s | follower-0 late ticks % | worst follower % | "
          "follower-0 CPU % | follower-0 refused / kernel drops | inside bounds | "
          "radius error m |")
    print("|---|---|---|---|---|---|---|---|")
    for name, dps, size in LEVELS:
        if args.only and name not in args.only:
            continue
        for _ in range(args.repeat):
            r = one_run(dps, size, args.duration)
            cpu = "?" if r["f0_cpu"] is None else f"{r['f0_cpu']:.0f}"
            print(f"| {name} | {r['mb_s']:.1f} | {r['f0_late']:.2f} | {r['worst_late']:.2f} | "
                  f"{cpu} | {r['refused']} / {r['kernel_drops']} | "
                  f"{'yes' if r['inside'] else 'NO'} | {r['radius_error_m']:.4f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
