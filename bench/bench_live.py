"""CPU cost of the recorder's live view (issue 14): view off, view into the MCAP only
(`enclose run --no-live`), and view served to one subscribed Foxglove client (the default).

Feeds a synthetic paper-case run (truth + 4 follower states at 50 Hz, plus each follower's
status with link counters once a second) through an in-memory bus into `Recorder.step()`
and `tick()`, one batch per second of experiment time, and prints the recorder process's
CPU time (all its threads, so the WebSocket server's too) per second of experiment.  The
client runs in its own process (tests/foxglove_client.py), subscribed to every channel.

Run: python -m bench.bench_live [--duration 60] [--repeats 3]   (from the repo root)
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

from agents.loading.scenario_file import load_scenario
from agents.scenario.model import Scenario
from deploy.recording.live_server import LiveServer
from deploy.recording.loop import Recorder
from tests.recorder_synth import SynthRun
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import FollowerState, Message, ProcessStatus, Stamper

START_S = 1_700_000_000.0
MODES = ("view off", "view to MCAP (--no-live)", "live + 1 client")
CLIENT = """
import sys
from websockets.exceptions import ConnectionClosed
from tests.foxglove_client import foxglove_client
with foxglove_client(sys.argv[1]) as c:
    c.wait_channels({"/scene", "/errors", "/links", "/status"}, 30.0)
    c.subscribe(sorted(c.channels))
    print("subscribed", flush=True)
    n = 0
    try:
        while got := c.receive(1000, 2.0):
            n += len(got)
    except ConnectionClosed:  # the recorder finished: the server is gone
        pass
print("received", n, flush=True)
"""


def with_statuses(scenario: Scenario, run: SynthRun) -> Iterator[tuple[str, Message]]:
    """The run's samples, plus every follower's status (ring-link counters) each second."""
    keys, sent = run.keys, [0] * scenario.n
    stampers = [Stamper(f"follower-{i}") for i in range(scenario.n)]
    next_s = START_S
    for key, msg in run.samples():
        yield key, msg
        if isinstance(msg, FollowerState):
            sent[msg.index] += 1
            if msg.index == scenario.n - 1 and msg.header.stamp_s >= next_s:
                next_s += 1.0
                for i in range(scenario.n):
                    c: dict[str, int] = {}
                    for j in scenario.neighbours(i):
                        c |= {f"rx_f{j}": sent[j], f"seq_last_f{j}": sent[j] - 1,
                              f"age_p50_us_f{j}": 2000, f"age_p99_us_f{j}": 9000}
                    st = ProcessStatus(stampers[i].header(msg.header.stamp_s), "follower", i,
                                       "running", c)
                    yield keys.status("follower", i), st


def one(scenario: Scenario, duration_s: float, mode: str) -> tuple[float, float]:
    """CPU seconds per second of experiment in `mode`: in the recorder's step and tick, and
    the whole process over the feed (the server's threads work between steps too; the
    synthetic swarm's encoding is the same in every mode)."""
    keys = SwarmKeys("bench")
    run = SynthRun(scenario, keys, START_S, duration_s=duration_s, pre_s=0.0, post_s=0.0)
    live = LiveServer("127.0.0.1", 0) if mode == MODES[2] else None
    client = None
    with tempfile.TemporaryDirectory() as tmp, MemoryBus(MemoryHub(), "rec") as rbus:
        sbus = MemoryBus(rbus.hub, "swarm")
        recorder = Recorder(rbus, "bench", scenario, Path(tmp), period_s=0.0, live=live,
                            scene_hz=None if mode == MODES[0] else 10.0)
        sbus.publish(keys.control(), encode(run.control(Stamper("l"), "start")))
        if live is not None:  # a first frame advertises the channels; then the client joins
            recorder.step()
            recorder.tick()
            client = subprocess.Popen([sys.executable, "-c", CLIENT, live.url],
                                      stdout=subprocess.PIPE, text=True)
        cpu, batch, per_s = 0.0, [], round(run.rate_hz) * (1 + scenario.n)
        whole0 = time.process_time()
        for key, msg in with_statuses(scenario, run):
            batch.append((key, encode(msg)))
            if len(batch) >= per_s:
                for k, payload in batch:
                    sbus.publish(k, payload)
                batch.clear()
                c0 = time.process_time()
                recorder.step()
                recorder.tick()
                cpu += time.process_time() - c0
        whole = time.process_time() - whole0
        recorder.finish()
        sbus.close()
    if client is not None:
        out, _ = client.communicate(timeout=60)
        print(f"    client: {out.strip().splitlines()[-1]}")
    return cpu / duration_s, whole / duration_s


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    scenario = load_scenario("paper")
    loop: dict[str, list[float]] = {m: [] for m in MODES}
    whole: dict[str, list[float]] = {m: [] for m in MODES}
    for r in range(args.repeats):
        for mode in MODES:
            a, b = one(scenario, args.duration, mode)
            loop[mode].append(1000 * a)
            whole[mode].append(1000 * b)
            print(f"  run {r + 1} {mode}: step+tick {loop[mode][-1]:.1f}, "
                  f"process {whole[mode][-1]:.1f} ms CPU / s")
    print(f"recorder CPU per second of experiment, paper case, {args.duration:g} s, "
          f"{args.repeats} repeats: median (min-max), ms CPU per s")
    print(f"  {'mode':28s} {'step+tick':>22s} {'whole process':>24s}")
    for mode in MODES:
        cells = [f"{statistics.median(v[mode]):6.1f} ({min(v[mode]):.1f}-{max(v[mode]):.1f})"
                 for v in (loop, whole)]
        print(f"  {mode:28s} {cells[0]:>22s} {cells[1]:>24s}")


if __name__ == "__main__":
    main()
