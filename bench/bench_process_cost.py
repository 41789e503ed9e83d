"""CPU of the simulator per vehicle-tick and of the recorder per message (issue 50).

`sim`: `python -m deploy.commands.sim` runs as a child with a run secret (every vehicle
enforces signing with its own key) while this process plays one agent per vehicle: a
signed SET_POSITION_TARGET_LOCAL_NED at the agents' rate, a HEARTBEAT a second, each
vehicle asked for the telemetry rates a follower asks (ATTITUDE and GLOBAL_POSITION_INT at
4 Hz; `--default-rates`: not asked, all three at 50 Hz), put in OFFBOARD and armed first,
and all telemetry drained.  The child's CPU over
all its threads (/proc/<pid>/stat, utime + stime) over a window after it settled, divided
by vehicles x ticks in the window.

`sim-phases`: the same simulator in this process, stepped by `step_once()` with the same
signed traffic queued before each tick, and thread CPU time around its phases: receive
(read, screen, verify, decode, dispatch), model (autopilots, control rows, physics, rows)
and telemetry (encode, sign, send).  Not paced: a tick's figures, not the loop's waits.

`recorder`: bench/bench_recorder_cost.py (the recorder's own loop, live view on).

    python bench/bench_process_cost.py sim [--vehicles 64] [--seconds 8] [--runs 5]
    python bench/bench_process_cost.py sim-phases [--vehicles 64] [--ticks 500]
"""

from __future__ import annotations

import argparse
import os
import re
import selectors
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.gcs_agents import HOST, Agents

CLK_TCK = os.sysconf("SC_CLK_TCK")
RATES = {False: "telemetry rates as a follower asks them",
         True: "the vehicles' default telemetry rates"}


def proc_cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def sim_run(n: int, seconds: float, rate_hz: float, agent_hz: float, base: int,
            ask_rates: bool = True) -> dict:
    listen, send = base, base + 1000
    sinks = []
    sel = selectors.DefaultSelector()
    for i in range(n):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        s.bind((HOST, send + i))
        s.setblocking(False)
        sel.register(s, selectors.EVENT_READ, i)
        sinks.append(s)
    secret = os.urandom(32)
    with tempfile.NamedTemporaryFile(delete=False) as f:
        f.write(secret)
    agents = Agents(secret, n, ask_rates)
    # ENCLOSE_BENCH_WRAP: a profiler's command line to run the simulator under (py-spy ...)
    wrap = os.environ.get("ENCLOSE_BENCH_WRAP", "").split()
    proc = subprocess.Popen(
        [*wrap, sys.executable, "-m", "deploy.commands.sim", "--vehicles", str(n), "--base-port",
         str(listen), "--send-base-port", str(send), "--rate-hz", str(rate_hz),
         "--signing-secret", f.name, "--duration-s", str(seconds + 4.0)],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    started = set()
    cpu0 = cpu1 = t0 = t1 = 0.0
    try:
        start = time.monotonic()
        settle_at, end_at = start + 3.0, start + 3.0 + seconds
        # Each agent ticks at its own phase, as followers do: vehicle i at i/n of a period.
        period = 1.0 / agent_hz
        due = [start + 0.5 + period * i / n for i in range(n)]
        ticks = [0] * n
        while time.monotonic() < end_at:
            now = time.monotonic()
            for i in range(n):
                if now < due[i]:
                    continue
                out = [agents.setpoint(i)]
                if now - start > 1.0 and i not in started:
                    out += agents.start(i)
                    started.add(i)
                if ticks[i] % round(agent_hz / 4) == 0:  # TIMESYNC 4 times a second
                    out.append(agents.timesync(i))
                if ticks[i] % round(agent_hz) == 0:
                    out.append(agents.heartbeat(i))
                for data in out:
                    sinks[i].sendto(data, (HOST, listen + i))
                ticks[i] += 1
                due[i] += period
            if not t0 and now >= settle_at:
                cpu0, t0 = proc_cpu_s(proc.pid), now
            for key, _ in sel.select(max(0.0, min(due) - time.monotonic())):
                while True:
                    try:
                        key.fileobj.recv(65535)  # type: ignore[union-attr]
                    except BlockingIOError:
                        break
        cpu1, t1 = proc_cpu_s(proc.pid), time.monotonic()
        os.kill(proc.pid, signal.SIGINT)
        out = proc.communicate(timeout=20.0)[0].decode()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        sel.close()
        for s in sinks:
            s.close()
        os.unlink(f.name)
    stats = dict(re.findall(r"(\w+)=([\d.]+)", out))
    ticks = (t1 - t0) * rate_hz
    handled = re.search(r"SET_POSITION_TARGET_LOCAL_NED:handled=(\d+)", out)
    return {"us_per_vehicle_tick": 1e6 * (cpu1 - cpu0) / (ticks * n),
            "cpu_pct": 100.0 * (cpu1 - cpu0) / (t1 - t0),
            "overrun_pct": 100.0 * int(stats.get("overruns", 0))
            / max(1, int(stats.get("ticks", 1))),
            "rejected": sum(int(v) for k, v in stats.items() if k.startswith("signing_rej")),
            "setpoints": int(handled[1]) if handled else 0}


def spread(values: list[float]) -> str:
    return (f"median {statistics.median(values):.1f} (min {min(values):.1f}, "
            f"max {max(values):.1f}, n={len(values)})")


def main_sim(args: argparse.Namespace) -> None:
    print(f"simulator: {args.vehicles} vehicles, tick {args.rate_hz:g} Hz; per vehicle "
          f"signed setpoints {args.agent_hz:g} Hz, TIMESYNC 4 Hz, HEARTBEAT 1 Hz; "
          f"{RATES[args.default_rates]}; "
          f"{args.seconds:g} s window after 3 s; load {os.getloadavg()[0]:.2f}")
    per = []
    for k in range(args.runs):
        r = sim_run(args.vehicles, args.seconds, args.rate_hz, args.agent_hz, args.base_port,
                    not args.default_rates)
        per.append(r["us_per_vehicle_tick"])
        print(f"  run {k + 1}: {r['us_per_vehicle_tick']:6.1f} us/vehicle-tick  "
              f"CPU {r['cpu_pct']:5.1f} %  overruns {r['overrun_pct']:.2f} %  setpoints "
              f"{r['setpoints']}  signing rejected {r['rejected']}  load "
              f"{os.getloadavg()[0]:.2f}", flush=True)
    print(f"sim us per vehicle-tick: {spread(per)}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=("sim", "sim-phases"))
    ap.add_argument("--vehicles", type=int, default=64)
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--ticks", type=int, default=500)
    ap.add_argument("--rate-hz", type=float, default=50.0)
    ap.add_argument("--agent-hz", type=float, default=50.0)
    ap.add_argument("--base-port", type=int, default=27000)
    ap.add_argument("--default-rates", action="store_true",
                    help="do not ask the followers' telemetry rates (all streams at 50 Hz)")
    args = ap.parse_args()
    if args.what == "sim":
        main_sim(args)
    else:
        from bench.sim_phases import main_phases

        main_phases(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
