"""A recorder stalled under load: its RSS before a stall, at the peak and after it has
caught up (issue "Hours, not minutes": a backlog's memory).

A real recorder on loopback records a synthetic paper's run at 250 Hz (five times the
paper's message rate); 12 s in, it is stopped (SIGSTOP) for 8 s while the feed goes on,
then let go to work the backlog off.  Printed: the largest RSS over the 4 s before the
stall, the peak, and the mean over the last 5 s.

Run: python bench/bench_backlog.py [--runs 2] [--out /tmp/backlog]
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from agents.loading.scenario_file import load_scenario
from deploy.report.cpu_load import process_status_kb
from tests.integration.test_recorder_process import (
    publish_paced,
    pubs_keys,
    start_recorder,
    stop,
    wait_for,
)
from tests.integration.test_transport_zenoh import free_port
from tests.recorder_synth import SynthRun
from transport.bus import Congestion, wait_until_alive
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.messages import Stamper
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig, loopback_endpoint

RUN_S, STALL_AT_S, STALL_S, RATE_HZ = 45.0, 12.0, 8.0, 250.0


def stalled_run(out: Path) -> tuple[float, float, float]:
    """(MB before the stall, peak MB, MB over the last 5 s) of one recorder."""
    swarm, endpoint = f"bl{os.getpid()}", loopback_endpoint(free_port())
    keys, scenario = SwarmKeys(swarm), load_scenario("paper")
    proc = start_recorder(swarm, out, endpoint)
    samples: list[tuple[float, float]] = []
    try:
        with ZenohBus(ZenohConfig(connect=(endpoint,))) as bus:
            wait_until_alive(bus.watch_alive(keys.all_alive()), {keys.alive("recorder", 0)}, 20)
            # BLOCK: a lossless feed (the recorder's backlog is measured, not the transport's).
            pubs = [bus.declare_publisher(k, Congestion.BLOCK) for k in pubs_keys(keys)]
            wait_for(lambda: all(p.matched() for p in pubs), 10, "the subscription")
            run = SynthRun(scenario, keys, time.time() + 0.5, duration_s=RUN_S,
                           rate_hz=RATE_HZ, pre_s=0.0, post_s=0.0)
            control = Stamper("launcher-0")
            bus.publish(keys.control(), encode(run.control(control, "start")))
            done = threading.Event()
            sampler = threading.Thread(target=sample, args=(proc.pid, done, samples),
                                       daemon=True)
            sampler.start()
            publish_paced(bus, run, garbage_at=-1, silent=None)
            done.set()
            sampler.join()
            bus.publish(keys.control(), encode(run.control(control, "stop")))
            wait_for(lambda: proc.poll() is not None, 90, "the recorder to exit")
    finally:
        stop(proc)
    t, mb = np.array(samples).T
    before = mb[(t > STALL_AT_S - 4.0) & (t < STALL_AT_S)].max()
    return float(before), float(mb.max()), float(mb[t > t[-1] - 5.0].mean())


def sample(pid: int, done: threading.Event, samples: list[tuple[float, float]]) -> None:
    """VmRSS every 0.5 s; the stall (SIGSTOP, then SIGCONT) at its times."""
    t0, state = time.monotonic(), "running"
    while not done.wait(0.5):
        t = time.monotonic() - t0
        if state == "running" and t >= STALL_AT_S:
            os.kill(pid, signal.SIGSTOP)
            state = "stopped"
        elif state == "stopped" and t >= STALL_AT_S + STALL_S:
            os.kill(pid, signal.SIGCONT)
            state = "resumed"
        samples.append((t, (process_status_kb(pid, "VmRSS") or 0) / 1024))


def main(runs: int, out: Path) -> None:
    for k in range(runs):
        before, peak, after = stalled_run(out / f"run{k}")
        print(f"run {k}: before the stall {before:.1f} MB, peak {peak:.1f} MB, "
              f"after {after:.1f} MB (+{after - before:.1f} MB)", flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("/tmp/backlog"))
    args = parser.parse_args()
    main(args.runs, args.out)
