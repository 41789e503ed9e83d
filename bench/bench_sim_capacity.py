"""How many vehicles one simulator process holds in real time with 50 Hz telemetry each.

For each fleet size N, `enclose sim` runs as a child process on loopback for a
fixed wall time while this process plays N ground stations: it drains every
vehicle's telemetry and (unless --no-setpoints) streams a 50 Hz velocity setpoint
to each.  Reported: ticks, tick overruns (%), the simulator's CPU use, and the
telemetry rate actually received per vehicle.  Bounded: about 10 s per size.

    python bench/bench_sim_capacity.py [--sizes 50,100,150,200,255] [--seconds 8]
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import selectors
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink2

HOST = "127.0.0.1"


@dataclass
class Result:
    vehicles: int
    ticks: int
    overruns: int
    cpu_pct: float
    rx_hz_per_vehicle: float
    lpos_hz_per_vehicle: float
    setpoints_handled_pct: float

    @property
    def overrun_pct(self) -> float:
        return 100.0 * self.overruns / max(self.ticks, 1)


def count_msg(data: bytes, msg_id: int) -> int:
    """How many MAVLink 2 packets with msg_id a datagram holds (header walk, no CRC check)."""
    count, o = 0, 0
    while o + 10 <= len(data) and data[o] == 0xFD:
        if data[o + 7] | data[o + 8] << 8 | data[o + 9] << 16 == msg_id:
            count += 1
        o += 12 + data[o + 1] + (13 if data[o + 2] & 1 else 0)
    return count


def open_sinks(base: int, n: int) -> list[socket.socket]:
    socks = []
    for i in range(n):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        s.bind((HOST, base + i))
        s.setblocking(False)
        socks.append(s)
    return socks


def setpoint_bytes(n: int) -> list[bytes]:
    out = []
    for i in range(n):
        mav = mavlink2.MAVLink(None, srcSystem=245, srcComponent=191)
        msg = mav.set_position_target_local_ned_encode(0, i + 1, 1, 1, 3527, 0, 0, 0, 1.0, 0.0,
                                                       0.0, 0, 0, 0, 0, 0)
        out.append(msg.pack(mav))
    return out


def drive(n: int, seconds: float, listen_base: int, send_base: int, setpoints: bool,
          rate_hz: float, telemetry_hz: float) -> Result:
    sinks = open_sinks(send_base, n)
    sel = selectors.DefaultSelector()
    for i, s in enumerate(sinks):
        sel.register(s, selectors.EVENT_READ, i)
    sp = setpoint_bytes(n)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.Popen(
        [sys.executable, "-m", "deploy.commands.sim", "--vehicles", str(n), "--base-port",
         str(listen_base), "--send-base-port", str(send_base), "--rate-hz", str(rate_hz),
         "--telemetry-hz", str(telemetry_hz), "--duration-s", str(seconds + 1.0)],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    datagrams = 0
    lpos = 0
    sent = 0
    try:
        start = time.monotonic()
        measure_from = start + 1.0  # skip start-up
        next_sp = start
        while proc.poll() is None and time.monotonic() < start + seconds + 10.0:
            now = time.monotonic()
            if setpoints and now >= next_sp:
                for i, data in enumerate(sp):
                    sinks[i].sendto(data, (HOST, listen_base + i))
                sent += n
                next_sp += 1.0 / 50.0
            for key, _ in sel.select(0.005):
                while True:
                    try:
                        data = key.fileobj.recv(65535)  # type: ignore[union-attr]
                    except BlockingIOError:
                        break
                    if time.monotonic() >= measure_from:
                        datagrams += 1
                        lpos += count_msg(data, 32)
        out = proc.communicate(timeout=10.0)[0].decode()
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()
        sel.close()
        for s in sinks:
            s.close()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    stats = dict(re.findall(r"(\w+)=([\d.]+)", out))
    wall = float(stats.get("wall_s", seconds))
    return Result(n, int(stats.get("ticks", 0)), int(stats.get("overruns", 0)),
                  100.0 * cpu_s / max(wall, 1e-9), datagrams / seconds / n, lpos / seconds / n,
                  100.0 * int(stats.get("setpoints", 0)) / sent if sent else 100.0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--sizes", default="50,100,150,200,255")
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--rate-hz", type=float, default=50.0)
    ap.add_argument("--telemetry-hz", type=float, default=50.0)
    ap.add_argument("--base-port", type=int, default=26000)
    ap.add_argument("--no-setpoints", action="store_true")
    args = ap.parse_args()
    setpoints = "off" if args.no_setpoints else "50 Hz"
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} CPUs, tick {args.rate_hz:g} Hz, "
          f"telemetry {args.telemetry_hz:g} Hz, setpoints {setpoints}")
    print(f"{'vehicles':>8} {'ticks':>6} {'overrun%':>9} {'sim CPU%':>9} "
          f"{'rx dgram/s/veh':>15} {'LPOS Hz/veh':>12} {'setpoints ok%':>14}")
    best = 0
    for n in (int(v) for v in args.sizes.split(",")):
        r = drive(n, args.seconds, args.base_port, args.base_port + 1000, not args.no_setpoints,
                  args.rate_hz, args.telemetry_hz)
        print(f"{r.vehicles:>8} {r.ticks:>6} {r.overrun_pct:>9.2f} {r.cpu_pct:>9.1f} "
              f"{r.rx_hz_per_vehicle:>15.1f} {r.lpos_hz_per_vehicle:>12.1f} "
              f"{r.setpoints_handled_pct:>14.1f}", flush=True)
        if r.overrun_pct < 1.0 and r.lpos_hz_per_vehicle >= 0.95 * args.telemetry_hz:
            best = max(best, n)
    print(f"largest fleet in real time (<1% overruns, full telemetry rate): {best} vehicles")
    return 0


if __name__ == "__main__":
    sys.exit(main())
