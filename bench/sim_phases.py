"""The simulator's tick split into phases, in this process (bench_process_cost.py sim-phases).

Each tick the agents' traffic for the tick is queued on the vehicles' sockets (its cost
not counted), then `step_once()` runs with thread CPU time around receive (read, screen,
verify, decode, dispatch), telemetry (encode, sign, send, clock service) and the rest of
the advance (autopilots, control rows, physics, rows): the model.
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import time

from agents.scenario.model import HomeConfig, VehicleConfig
from bench.gcs_agents import HOST, Agents
from sim_backend.runtime import SimConfig, Simulator, grid_spawn_ned


def _timed(fn, acc: list[int]):  # type: ignore[no-untyped-def]
    def wrapped(*a, **k):  # type: ignore[no-untyped-def]
        t0 = time.thread_time_ns()
        try:
            return fn(*a, **k)
        finally:
            acc[0] += time.thread_time_ns() - t0
    return wrapped


def phases_once(n: int, ticks: int, rate_hz: float, ask_rates: bool = True) -> dict[str, float]:
    secret = os.urandom(32)
    cfg = SimConfig(rate_hz=rate_hz, telemetry_hz=rate_hz, listen_base_port=0,
                    send_base_port=28000, signing_secret=secret)
    sim = Simulator(grid_spawn_ned(n), VehicleConfig(), HomeConfig(), cfg)
    agents = Agents(secret, n, ask_rates)
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind((HOST, 0))
    sink.setblocking(False)
    sink.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    for ep in sim.endpoints:  # telemetry to one sink, drained outside the timing
        ep.default_dest = sink.getsockname()
    ports = sim.listen_ports()
    rx, tel = [0], [0]
    sim.receive_until = _timed(sim.receive_until, rx)  # type: ignore[method-assign]
    for i, ep in enumerate(sim.endpoints):
        ep.telemetry = _timed(ep.telemetry, tel)  # type: ignore[method-assign]
        sim.clocks[i].due = _timed(sim.clocks[i].due, tel)  # type: ignore[method-assign]
    total = 0
    per_tick = round(rate_hz / 50.0) or 1
    try:
        for k in range(ticks + 50):
            if k == 50:  # settled: armed and flying
                rx[0] = tel[0] = total = 0
            for i in range(n):
                out = [agents.setpoint(i)] if k % per_tick == 0 else []
                if k == 10:
                    out += agents.start(i)
                if k % max(1, round(rate_hz / 4)) == i % 4:
                    out.append(agents.timesync(i))
                if k % round(rate_hz) == 0:
                    out.append(agents.heartbeat(i))
                for data in out:
                    sink.sendto(data, (HOST, ports[i]))
            t0 = time.thread_time_ns()
            sim.step_once()
            total += time.thread_time_ns() - t0
            while True:
                try:
                    sink.recv(65535)
                except BlockingIOError:
                    break
        armed = sum(ep.autopilot.armed for ep in sim.endpoints)
    finally:
        sim.close()
        sink.close()
    vt = n * ticks * 1000.0  # ns -> us per vehicle-tick
    return {"receive": rx[0] / vt, "model": (total - rx[0] - tel[0]) / vt,
            "telemetry": tel[0] / vt, "total": total / vt, "armed": armed}


def main_phases(args: argparse.Namespace) -> None:
    print(f"simulator phases, in process: {args.vehicles} vehicles, {args.ticks} ticks at "
          f"{args.rate_hz:g} Hz (unpaced), thread CPU per vehicle-tick; load "
          f"{os.getloadavg()[0]:.2f}")
    rows = []
    for k in range(args.runs):
        r = phases_once(args.vehicles, args.ticks, args.rate_hz, not args.default_rates)
        rows.append(r)
        print(f"  run {k + 1}: receive {r['receive']:5.1f}  model {r['model']:5.1f}  "
              f"telemetry {r['telemetry']:5.1f}  total {r['total']:5.1f} us  "
              f"(armed {r['armed']:.0f})", flush=True)
    for name in ("receive", "model", "telemetry", "total"):
        v = [r[name] for r in rows]
        print(f"  {name:9s} median {statistics.median(v):6.1f} us (min {min(v):.1f}, "
              f"max {max(v):.1f})")
