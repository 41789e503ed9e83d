"""Start-up, phase by phase, and memory per role (issue 15: fast start, lean processes).

Runs `enclose run SCENARIO --duration D` (mTLS + access control and MAVLink signing on,
as by default) and times each phase on CLOCK_MONOTONIC, which the bench, the launcher
and every process it starts share (agents.shell.phases):

  launcher:  exec, credentials (made), spawned (all children), bus_open, linked (all tokens)
  follower:  spawn (launcher's Popen), exec, main (imports done), bus_open (Zenoh session,
             TLS included), heartbeat (vehicle's HEARTBEAT), position (telemetry + home),
             armed (ARM accepted), takeoff_accepted, at_altitude, offboard, linked (token)

"linked and armed, take-off excluded" = the command -> all linked, minus the climb
(takeoff_accepted -> at_altitude) of each vehicle: max over followers and targets of
(linked - climb), plus the launcher's own delay in seeing the last token.
Memory: VmRSS of every child, sampled every 0.25 s (max), and VmHWM, per role.

Run: python bench/bench_start.py [--cases paper ring16] [--repeats 3] [--duration 2]
     [--insecure] [--out runs/bench-start]
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

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from agents.shell.phases import parse_phases
from deploy.procs.pids import read_pids
from deploy.report.cpu_load import process_status_kb

FOLLOWER_PHASES = ("spawn", "exec", "main", "bus_open", "node", "heartbeat", "position", "armed",
                   "takeoff_accepted", "at_altitude", "offboard", "linked")
LAUNCHER_PHASES = ("exec", "credentials", "spawned", "bus_open", "linked")


def rollup_kb(pid: int) -> dict[str, int]:
    """Pss and private (USS) kB: the memory a process costs beyond what it shares."""
    out = {"pss_kb": 0, "uss_kb": 0}
    try:
        for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
            key, _, rest = line.partition(":")
            if key == "Pss":
                out["pss_kb"] = int(rest.split()[0])
            elif key in ("Private_Clean", "Private_Dirty"):
                out["uss_kb"] += int(rest.split()[0])
    except (OSError, ValueError, IndexError):
        pass
    return out


def role_of(name: str) -> str:
    return name.split("-")[0]


def sample_memory(proc: subprocess.Popen[bytes], out: Path) -> dict[str, dict[str, int]]:
    """Per child: max VmRSS, VmHWM, Pss and USS seen, in kB, until the run ends."""
    mem: dict[str, dict[str, int]] = {}
    while proc.poll() is None:
        for name, pid in ((k, v.pid) for k, v in read_pids(out / "logs").items()):
            rss, hwm = process_status_kb(pid, "VmRSS"), process_status_kb(pid, "VmHWM")
            if rss is not None and hwm is not None:
                m = mem.setdefault(name, {"rss_kb": 0, "hwm_kb": 0, "pss_kb": 0, "uss_kb": 0})
                now = {"rss_kb": rss, "hwm_kb": hwm, **rollup_kb(pid)}
                for key, value in now.items():
                    m[key] = max(m[key], value)
        time.sleep(0.25)
    return mem


def process_phases(out: Path, launch: dict[str, Any], t0: float) -> dict[str, dict[str, float]]:
    """Every child's phase stamps relative to the command (s), with its CPU seconds."""
    res: dict[str, dict[str, float]] = {}
    for name, info in launch["processes"].items():
        log_path = out / "logs" / f"{name}.log"
        lines = log_path.read_text(errors="replace").splitlines() if log_path.exists() else []
        parsed = next((p for p in map(parse_phases, lines) if p is not None), None)
        if parsed is None or info.get("spawned_s") is None:
            continue
        stamps, cpu_s = parsed
        res[name] = {"spawn": info["spawned_s"] - t0, **{k: v - t0 for k, v in stamps.items()},
                     "cpu_s": cpu_s}
    return res


def summarise(launch: dict[str, Any], procs: dict[str, dict[str, float]],
              t0: float) -> dict[str, Any]:
    lp = {k: v - t0 for k, v in launch.get("start_phases", {}).items()}
    movers = {n: p for n, p in procs.items() if "at_altitude" in p and "linked" in p}
    followers = {n: p for n, p in movers.items() if n.startswith("follower")}
    last_linked = max(p["linked"] for p in procs.values() if "linked" in p)
    seen_after_s = lp["linked"] - last_linked  # the launcher's delay in seeing the last token
    ready = {n: p["linked"] - (p["at_altitude"] - p["takeoff_accepted"])
             for n, p in movers.items()}
    others = [p["linked"] for n, p in procs.items() if n not in movers and "linked" in p]
    return {
        "command_to_all_linked_s": lp["linked"],
        "linked_and_armed_excl_takeoff_s": max([*ready.values(), *others]) + seen_after_s,
        "all_followers_armed_s": max(p["armed"] for p in followers.values()),
        "climb_s_max": max(p["at_altitude"] - p["takeoff_accepted"] for p in movers.values()),
        "launcher": lp,
        "follower_phase_end_s": {  # max and median over followers, from the command
            ph: [round(max(p[ph] for p in followers.values()), 3),
                 round(statistics.median(p[ph] for p in followers.values()), 3)]
            for ph in FOLLOWER_PHASES if all(ph in p for p in followers.values())
        },
        "cpu_s_at_linked": {role: round(max(p["cpu_s"] for n, p in procs.items()
                                            if role_of(n) == role), 3)
                            for role in sorted({role_of(n) for n in procs})},
    }


def run_once(case: str, duration_s: float, out: Path, insecure: bool) -> dict[str, Any]:
    argv = [sys.executable, "-m", "deploy.cli", "run", case, "--duration", str(duration_s),
            "--out", str(out), *(["--insecure"] if insecure else [])]
    t0 = time.monotonic()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        mem = sample_memory(proc, out)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    launch = json.loads((out / "launch.json").read_text())
    procs = process_phases(out, launch, t0)
    summary = summarise(launch, procs, t0)
    roles: dict[str, dict[str, float]] = {}
    for name, m in mem.items():
        r = roles.setdefault(role_of(name), {})
        for key in ("rss", "hwm", "pss", "uss"):
            r[f"{key}_mb_max"] = max(r.get(f"{key}_mb_max", 0.0), round(m[f"{key}_kb"] / 1024, 1))
    return {"exit_code": proc.returncode, **summary, "memory": roles}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", nargs="+", default=["paper", "ring16"])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--duration", type=float, default=2.0)
    parser.add_argument("--insecure", action="store_true")
    parser.add_argument("--out", type=Path, default=Path("runs/bench-start"))
    args = parser.parse_args()
    for case in args.cases:
        runs = []
        for k in range(args.repeats):
            out = (args.out / f"{case}-{k}").resolve()
            result = run_once(case, args.duration, out, args.insecure)
            print(f"== {case} run {k + 1}: {out}")
            print(json.dumps(result), flush=True)
            runs.append(result)
        for key in ("linked_and_armed_excl_takeoff_s", "command_to_all_linked_s",
                    "all_followers_armed_s"):
            vals = sorted(round(r[key], 2) for r in runs)
            print(f"{case}: {key} median {statistics.median(vals):.2f} s, runs {vals}")
        for key in ("rss", "hwm", "pss", "uss"):
            fol = [r["memory"].get("follower", {}).get(f"{key}_mb_max", 0.0) for r in runs]
            print(f"{case}: follower {key} max {max(fol):.1f} MB (runs {fol})", flush=True)


if __name__ == "__main__":
    main()
