"""The recorder process's CPU per message recorded, with its live view on (issue 50).

A real recorder (`python -m deploy.recording.recorder --live-port 0`) on a Zenoh loopback bus (plain
TCP, no mTLS: the bench's publisher holds no certificate) records a synthetic run
(tests/recorder_synth.py: truth + every follower's state at --rate-hz, paced on the wall
clock as the swarm sends them).  Its CPU over all its threads (/proc/<pid>/stat), from a
progress.json write after it settled to the first one after it has recorded all it was
sent, per message it recorded in between (progress.json's count: a recorder starved on
a busy machine works its backlog off after the feed, and that is counted too), and per
thread group (the main thread, Zenoh's, the live view's server).

    python bench/bench_recorder_cost.py [--case ring64] [--rate-hz 50] [--seconds 10] [--runs 5]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agents.loading.scenario_file import load_scenario
from tests.integration.test_transport_zenoh import free_port
from tests.recorder_synth import SynthRun
from transport.bus import wait_until_alive
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.messages import Stamper
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig, loopback_endpoint

CLK_TCK = os.sysconf("SC_CLK_TCK")
SETTLE_S = 4.0
QUIET_MESSAGES = 30  # recorded in a second once the feed has ended: statuses only


def threads_cpu_s(pid: int) -> dict[str, float]:
    """CPU seconds per thread group (thread names without their number; the main thread
    apart from the other Python threads, the live view's server)."""
    out: dict[str, float] = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            text = (task / "stat").read_text()
        except OSError:
            continue
        name = re.sub(r"[-_]?\d+$", "", text[text.index("(") + 1:text.rindex(")")])
        name = "main" if task.name == str(pid) else name
        fields = text.rpartition(")")[2].split()
        out[name] = out.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / CLK_TCK
    return out


def one_run(case: str, rate_hz: float, seconds: float, out: Path) -> dict:
    swarm, endpoint = f"rc{os.getpid()}", loopback_endpoint(free_port())
    keys, scenario = SwarmKeys(swarm), load_scenario(case)
    proc = subprocess.Popen(
        [sys.executable, "-m", "deploy.recording.recorder", "--scenario", case, "--swarm", swarm,
         "--out", str(out), "--listen", endpoint, "--live-port", "0", "--no-figures"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    window: dict[str, float] = {}
    try:
        with ZenohBus(ZenohConfig(connect=(endpoint,))) as bus:
            wait_until_alive(bus.watch_alive(keys.all_alive()), {keys.alive("recorder", 0)}, 30)
            run = SynthRun(scenario, keys, time.time() + 0.5, duration_s=SETTLE_S + seconds + 1,
                           rate_hz=rate_hz, pre_s=0.0, post_s=0.0)
            control = Stamper("launcher-0")
            bus.publish(keys.control(), encode(run.control(control, "start")))
            t_start = run.start_stamp_s
            sent_by = t_start + SETTLE_S + seconds + 1.0  # the feed's end: duration_s below
            sampler = threading.Thread(target=_sample, args=(
                proc.pid, out / "progress.json", t_start, seconds, sent_by, window))
            sampler.start()
            sent = _publish(bus, run)
            sampler.join()
            bus.publish(keys.control(), encode(run.control(control, "stop")))
            proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    rec = json.loads((out / "metrics.json").read_text())["recorder"]
    msgs_per_s = (scenario.n + 1) * rate_hz
    cpu, wall, msgs = window.pop("_total"), window.pop("_wall"), window.pop("_messages")
    return {"us_per_msg": 1e6 * cpu / msgs, "cpu_pct": 100 * cpu / wall,
            "recorded": rec["messages_total"], "sent": sent, "msgs_per_s": msgs_per_s,
            "threads": {k: 100 * v / wall for k, v in sorted(window.items(), key=lambda x: -x[1])},
            "frames": rec["live"]["frames_per_topic"]}


def _publish(bus: ZenohBus, run: SynthRun) -> int:
    pubs: dict[str, object] = {}
    sent = 0
    for key, msg in run.samples():
        delay = msg.header.stamp_s - time.time()
        if delay > 0:
            time.sleep(delay)  # the swarm's own pace, not a synchronisation
        pub = pubs.get(key) or pubs.setdefault(key, bus.declare_publisher(key))
        pub.put(encode(msg))  # type: ignore[attr-defined]
        sent += 1
    return sent


def _sample(pid: int, progress: Path, t_start: float, seconds: float, sent_by: float,
            into: dict[str, float]) -> None:
    """CPU and messages recorded from the first progress.json write after the recorder
    settled to the first one after it recorded everything sent (a starved recorder works a
    backlog off after the feed: its CPU for it counts, its messages too)."""
    time.sleep(max(0.0, t_start + SETTLE_S - time.time()))
    m0, a, t0 = _at_progress_write(pid, progress)
    time.sleep(max(0.0, t_start + SETTLE_S + seconds - time.time()))
    prev = -1
    while True:  # until a second after the feed's end in which (almost) nothing came
        m1, b, t1 = _at_progress_write(pid, progress)
        if time.time() > sent_by and 0 <= m1 - prev <= QUIET_MESSAGES:
            break
        prev = m1
    for k, v in b.items():
        into[k] = v - a.get(k, 0.0)
    into["_total"] = sum(into.values())
    into["_wall"] = t1 - t0
    into["_messages"] = m1 - m0


def _messages(progress: Path) -> int:
    try:
        return int(json.loads(progress.read_text())["messages_total"])
    except (OSError, ValueError, KeyError):
        return -1


def _at_progress_write(pid: int, progress: Path) -> tuple[int, dict[str, float], float]:
    """(messages recorded, CPU per thread group, time) just after progress.json changed."""
    first = _messages(progress)
    while True:
        now = _messages(progress)
        if now != first and now >= 0:
            return now, threads_cpu_s(pid), time.monotonic()
        time.sleep(0.002)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--case", default="ring64")
    ap.add_argument("--rate-hz", type=float, default=50.0)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    print(f"recorder, {args.case} feed at {args.rate_hz:g} Hz, live view on, {args.seconds:g} s "
          f"window after {SETTLE_S:g} s; load {os.getloadavg()[0]:.2f}")
    per = []
    for k in range(args.runs):
        with tempfile.TemporaryDirectory() as tmp:
            r = one_run(args.case, args.rate_hz, args.seconds, Path(tmp) / "run")
        per.append(r["us_per_msg"])
        threads = ", ".join(f"{n} {v:.1f}%" for n, v in list(r["threads"].items())[:6])
        print(f"  run {k + 1}: {r['us_per_msg']:6.1f} us/msg  CPU {r['cpu_pct']:5.1f} % at "
              f"{r['msgs_per_s']:.0f} msg/s (recorded {r['recorded']} of {r['sent']} sent); "
              f"threads: {threads}; load {os.getloadavg()[0]:.2f}", flush=True)
    print(f"recorder us per message: median {statistics.median(per):.1f} (min {min(per):.1f}, "
          f"max {max(per):.1f}, n={len(per)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
