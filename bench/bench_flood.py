"""MAVLink flood: does an agent (or the simulator) keep its ticks on time while a local
process floods its MAVLink port with badly signed datagrams?

    python bench/bench_flood.py [--seconds 10] [--repeat 3] [--only NAME ...]
    python bench/bench_flood.py --legacy /path/to/older/checkout   # the same, older code

Per run, three processes: the simulator (`deploy.commands.sim`, one signing vehicle), a victim
agent (this script with --victim: the project's MavlinkAdapter flying vehicle 1 at 50 Hz
on the project's Ticker, velocity setpoints each tick, as a follower's loop does without
its law) and a flooder (tests/integration/mav_insider.py: datagrams of frames signed with
a key nobody holds, in the vehicle's name).  Each level floods the agent's port or the
vehicle's at R datagrams/s of B bytes.  Reported per level (median of the runs, worst in
brackets): the victim's late ticks (20 ms slots of the Ticker's grid in which no tick
started: a tick a period or more late, as the Ticker's overruns, every slot of a stall
counted),
its poll time p99 and max, its CPU (% of one core), whether it kept the link and the
vehicle armed in offboard, its refusal and drop counters; the simulator's late ticks and
CPU over the flood.  `--legacy DIR` runs the simulator and the victim from another
checkout (one signing key for every vehicle, as before keys per vehicle) for a before/after,
e.g. `git archive <commit> | tar -x -C /tmp/before`.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
PERIOD_S = 0.02  # a follower's loop at 50 Hz
# name, what is flooded, datagrams/s, bytes per datagram (6 MB/s unless said)
LEVELS = (("none", "agent", 0, 0), ("agent 100/s x 60 KB", "agent", 100, 60_000),
          ("agent 1000/s x 6 KB", "agent", 1000, 6_000),
          ("agent 5000/s x 1.2 KB", "agent", 5000, 1_200),
          ("agent 20000/s x 300 B", "agent", 20_000, 300),
          ("sim 100/s x 60 KB", "sim", 100, 60_000), ("sim 5000/s x 1.2 KB", "sim", 5000, 1_200))


def victim(args: argparse.Namespace) -> int:
    """The agent under flood: fly vehicle 1, then `--seconds` of 50 Hz ticks, measured."""
    from agents.mavlink.adapter import AdapterConfig, MavlinkAdapter
    from agents.mavlink.signing_keys import load_key
    from agents.mavlink.startup import StartupTimeouts, start_offboard
    from agents.shell.process import Ticker

    cfg = AdapterConfig(local_port=args.local_port, remote_port=args.vehicle_port,
                        target_sysid=1, signing_key=load_key(args.key), signing_link_id=0)
    with MavlinkAdapter(cfg) as ad:
        start_offboard(ad, 2.0, StartupTimeouts(heartbeat_s=20.0, takeoff_s=30.0))
        Path(args.ready).write_text("ready")
        ticker = Ticker(PERIOD_S, time.monotonic)
        polls, starts, bad_ticks = [], [], 0
        t0, end = os.times(), time.monotonic() + args.seconds
        while time.monotonic() < end:
            starts.append(ticker.wait())
            start = time.perf_counter()
            state = ad.poll()
            ad.send_velocity_enu((0.0, 0.0, 0.0))
            polls.append(time.perf_counter() - start)
            bad_ticks += not (state.link_ok and state.armed and state.mode == "OFFBOARD")
        t1 = os.times()
    polls.sort()
    # A slot of the Ticker's grid (k * 20 ms on the clock) in which no tick started: its
    # tick came a period or more late (the Ticker's overrun), or never (the Ticker counts
    # a long stall as one overrun; here it costs every slot it spans).
    first, last = int(starts[0] / PERIOD_S), int(time.monotonic() / PERIOD_S)
    hit = {int(t / PERIOD_S) for t in starts}
    report = {"ticks": ticker.ticks, "overruns": ticker.overruns, "bad_ticks": bad_ticks,
              "late_pct": 100 * (last - first - len(hit & set(range(first, last)))) /
              max(1, last - first),
              "poll_p99_ms": 1e3 * polls[int(0.99 * (len(polls) - 1))],
              "poll_max_ms": 1e3 * polls[-1],
              "cpu_pct": 100 * (t1.user + t1.system - t0.user - t0.system) / args.seconds,
              **{k: v for k, v in ad.counters.items()
                 if k.startswith(("signing_", "mav_", "bad_packets"))}}
    Path(args.out).write_text(json.dumps(report))
    return 0


def process_cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def free_port_block(count: int) -> int:
    from tests.integration.sim_process import free_port_block as block
    return block(count)


def wait_file(path: Path, proc: subprocess.Popen[bytes], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not path.exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"victim not ready (exit {proc.poll()})")
        time.sleep(0.01)


def stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)


def sim_figures(log: str) -> dict[str, int]:
    for line in log.splitlines():
        if line.startswith("sim stopped:"):
            pairs = (item.split("=", 1) for item in line.split(":", 1)[1].split())
            return {k: int(float(v)) for k, v in pairs}
    return {}


def keys(tmp: Path, legacy: bool) -> tuple[list[str], Path]:
    """The simulator's signing arguments and the victim's key file."""
    from agents.mavlink.signing_keys import vehicle_key, write_key, write_raw_key
    secret = write_key(tmp / "secret.bin")
    if legacy:  # before keys per vehicle: one key, everywhere
        return ["--signing-key", str(tmp / "secret.bin")], tmp / "secret.bin"
    write_raw_key(tmp / "v1.bin", vehicle_key(secret, 1))
    return ["--signing-secret", str(tmp / "secret.bin")], tmp / "v1.bin"


def one_run(level: tuple[str, str, int, int], seconds: float, code: Path,
            legacy: bool) -> dict[str, Any]:
    _name, target, dps, size = level
    env = {**os.environ, "PYTHONPATH": str(code)}
    own_env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with tempfile.TemporaryDirectory(prefix="bench-flood-") as tmp_dir:
        tmp = Path(tmp_dir)
        signing, key = keys(tmp, legacy)
        vbase, abase = free_port_block(1), free_port_block(1)
        with (tmp / "sim.log").open("wb") as log:
            sim = subprocess.Popen([sys.executable, "-m", "deploy.commands.sim", "--vehicles", "1",
                                    "--base-port", str(vbase), "--send-base-port", str(abase),
                                    *signing], stdout=log, stderr=subprocess.STDOUT, env=env,
                                   cwd=code)  # `-m` puts the working directory first
        vic = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--victim",
                                "--local-port", str(abase), "--vehicle-port", str(vbase),
                                "--key", str(key), "--seconds", str(seconds),
                                "--ready", str(tmp / "ready"), "--out", str(tmp / "v.json")],
                               env=env, cwd=code)
        flood = None
        try:
            wait_file(tmp / "ready", vic, 60.0)
            sim_cpu0 = process_cpu_s(sim.pid)
            port = abase if target == "agent" else vbase
            flood = subprocess.Popen([sys.executable, "-m", "tests.integration.mav_insider",
                                      "--seconds", str(seconds), "--out", str(tmp / "f.json"),
                                      "--flood-port", str(port), "--flood-dps", str(dps),
                                      "--flood-size", str(max(size, 1))], env=own_env)
            vic.wait(seconds + 60)
            sim_cpu = 100 * (process_cpu_s(sim.pid) - sim_cpu0) / seconds
            flood.wait(30)
        finally:
            for proc in (vic, flood, sim):
                if proc is not None:
                    stop(proc)
        out = json.loads((tmp / "v.json").read_text())
        fl = json.loads((tmp / "f.json").read_text())
        s = sim_figures((tmp / "sim.log").read_text(errors="replace"))
    return {**out, "sim_cpu_pct": sim_cpu,
            "sim_late_pct": 100 * s.get("overruns", 0) / max(1, s.get("ticks", 1)),
            "sim_refused": sum(v for k, v in s.items() if k.startswith("signing_rejected_")),
            "sim_budget_spent": s.get("mav_budget_spent", 0),
            "flood_dps": fl["flood_sent"] / seconds,
            "flood_mb_s": fl["flood_bytes"] / seconds / 1e6,
            "flood_errors": fl["flood_errors"]}


def cell(runs: list[dict[str, Any]], key: str, fmt: str = "{:.2f}") -> str:
    values = [float(r.get(key, 0)) for r in runs]
    med, worst = statistics.median(values), max(values)
    return fmt.format(med) + (f" ({fmt.format(worst)})" if len(values) > 1 else "")


def row(name: str, runs: list[dict[str, Any]]) -> str:
    refused = sum(v for k, v in runs[-1].items() if k.startswith("signing_rejected_"))
    kept = "yes" if all(r["bad_ticks"] == 0 for r in runs) else \
        f"no ({max(r['bad_ticks'] for r in runs)} ticks)"
    return (f"| {name} | {cell(runs, 'flood_mb_s', '{:.1f}')} | {cell(runs, 'late_pct')} | "
            f"{cell(runs, 'poll_p99_ms')} | {cell(runs, 'poll_max_ms', '{:.1f}')} | "
            f"{cell(runs, 'cpu_pct', '{:.0f}')} | {kept} | {refused} / "
            f"{runs[-1].get('mav_kernel_drops', 0)} / {runs[-1].get('mav_flood_drops', 0)} | "
            f"{cell(runs, 'sim_late_pct')} | {cell(runs, 'sim_cpu_pct', '{:.0f}')} | "
            f"{runs[-1]['sim_refused']} |")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--only", nargs="*", default=None, help="level names to run")
    p.add_argument("--legacy", type=Path, default=None, metavar="DIR",
                   help="run the simulator and the victim from this checkout")
    p.add_argument("--victim", action="store_true", help=argparse.SUPPRESS)
    for name in ("--local-port", "--vehicle-port"):
        p.add_argument(name, type=int, help=argparse.SUPPRESS)
    for name in ("--key", "--ready", "--out"):
        p.add_argument(name, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.victim:
        return victim(args)
    code = (args.legacy or ROOT).resolve()
    print(f"code: {code} ({'one key for all vehicles' if args.legacy else 'a key per vehicle'})"
          f", {args.repeat} x {args.seconds:g} s per level")
    print("| level | flood MB/s | agent late ticks % | poll p99 ms | poll max ms | agent CPU % "
          "| link, armed, offboard kept | agent refused / kernel drops / cut | "
          "sim late ticks % | sim CPU % | sim refused |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for level in LEVELS:
        if args.only and level[0] not in args.only:
            continue
        runs = [one_run(level, args.seconds, code, args.legacy is not None)
                for _ in range(args.repeat)]
        print(row(level[0], runs), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
