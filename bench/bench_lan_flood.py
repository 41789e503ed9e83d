"""A flood from the LAN, no key needed (issue 51, item 6): garbage and 8-byte HEARTBEAT
prefixes at R datagrams a second, from another address.

    python bench/bench_lan_flood.py [--seconds 30] [--dps 30000] [--size 1000] [--repeat 2]
    python bench/bench_lan_flood.py --paper [--seconds 30]   # root: enclose run --hosts 2

Default: one vehicle of `enclose sim` listening on every address, flown by the project's
adapter, both ends flooded from 127.0.0.2 (tests/integration/lan_flood.py); `open` (both
hear anyone, as before) and `closed` (each hears its peer alone) alternate.  `--paper`:
the paper's case under `enclose run --hosts 2`, the simulator's host's address flooded
at every vehicle's port from a LAN address of the hub (10.77.0.200); the run's failsafes,
setpoints and verdict.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict
from pathlib import Path

from tests.integration.lan_flood import fly_flooded
from tests.integration.runs import spawned, wait_for

LAN_SOURCE = "10.77.0.200"
VEHICLES = re.compile(r"vehicles on UDP [\d.]+:(\d+)")


def component(args: argparse.Namespace) -> None:
    for k in range(args.repeat):
        for closed in (False, True):
            r = fly_flooded(args.seconds, args.dps, args.size, closed=closed)
            row = {k: v for k, v in asdict(r).items() if k != "agent_counters"}
            agent = {k: v for k, v in r.agent_counters.items() if k in (
                "link_losses", "mav_kernel_drops", "bad_packets", "peer_unreachable")}
            print(json.dumps({"run": k, "closed": closed, **row, "agent": agent}), flush=True)


def paper(args: argparse.Namespace) -> None:
    with tempfile.TemporaryDirectory(prefix="bench-lan-flood-") as tmp:
        out = Path(tmp) / "run"
        argv = [sys.executable, "-m", "deploy.cli", "run", "--hosts", "2", "--out", str(out),
                "--no-live", "--duration", str(args.seconds + 10.0)]
        with spawned(argv, out) as proc:
            hub = f"enclose-{proc.pid}-hub"
            base, lines = _vehicle_base(proc)
            wait_for(lambda: _t_s(out) >= 3.0, 120.0, "the run's experiment")
            dep = (out / "deployment.toml").read_text()
            sim_addr = re.search(r'address = "([\d.]+)"', dep).group(1)  # type: ignore[union-attr]
            subprocess.run(["ip", "-n", hub, "addr", "add", f"{LAN_SOURCE}/24", "dev", "br0"],
                           check=True)
            ports = [a for v in range(6) for a in ("--flood-port", str(base + v))]
            reports = [Path(tmp) / f"flood-{k}.json" for k in range(args.flooders)]
            t0 = time.monotonic()
            flooders = [subprocess.Popen(
                ["ip", "netns", "exec", hub, sys.executable, "-m",
                 "tests.integration.mav_insider", "--seconds", str(args.seconds), "--out",
                 str(report), "--flood-kind", "lan", "--flood-from", LAN_SOURCE, "--flood-host",
                 sim_addr, *ports, "--flood-dps", str(args.dps / args.flooders), "--flood-size",
                 str(args.size)]) for report in reports]
            for flooder in flooders:  # each exits after its seconds
                flooder.wait(args.seconds + 60.0)
            flood_s = time.monotonic() - t0
            proc.wait(timeout=args.seconds + 120.0)
            output = "".join(lines)
        launch = json.loads((out / "launch.json").read_text())
        sim = launch["status_at_stop"]["sim-0"]
        sent = sum(json.loads(r.read_text())["flood_sent"] for r in reports)
        verdict = [line for line in output.splitlines() if "bounds" in line][-1:]
        print(json.dumps({"flood_s": round(flood_s, 1), "flood_sent": sent,
                          "flood_dps": round(sent / args.seconds),
                          "failsafes": sim.get("failsafes", 0), "setpoints": sim.get("setpoints"),
                          "sim_rx_datagrams": sim.get("rx_datagrams"),
                          "sim_budget_spent": sim.get("mav_budget_spent", 0),
                          "ticks": sim.get("ticks"), "verdict": verdict}), flush=True)


def _t_s(out: Path) -> float:
    try:
        return float(json.loads((out / "progress.json").read_text()).get("t_s") or 0.0)
    except (OSError, ValueError):
        return 0.0


def _vehicle_base(proc: subprocess.Popen[str]) -> tuple[int, list[str]]:
    """The run's vehicle base port from its first lines; the rest of its output is read
    into the returned list by a thread (a full pipe would stall the launcher)."""
    assert proc.stdout is not None
    lines: list[str] = []
    for line in proc.stdout:
        lines.append(line)
        if (m := VEHICLES.search(line)) is not None:
            threading.Thread(target=lambda: lines.extend(proc.stdout or ()), daemon=True).start()
            return int(m.group(1)), lines
    raise RuntimeError("".join(lines[-20:]))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--seconds", type=float, default=30.0)
    p.add_argument("--dps", type=float, default=30_000.0)
    p.add_argument("--size", type=int, default=1_000)
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--paper", action="store_true")
    p.add_argument("--flooders", type=int, default=3, help="processes sharing the flood")
    args = p.parse_args()
    (paper if args.paper else component)(args)


if __name__ == "__main__":
    main()
