"""Cost of the recorder's loop on a long synthetic run (issue: recorder).

Feeds a perfect-formation run of the paper's case (truth + n follower states at 50 Hz, one
batch per second of experiment time) through an in-memory bus into `Recorder.step()`, and
prints: decode + MCAP + assembly throughput, CPU per message, the progress tick cost at the
end of the run, the final outputs time (assembly, metrics, CSV, figures) and MCAP size.

Run: python -m bench.bench_recorder [--duration 200] [--case paper]
(from the repo root: it reuses tests/)
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

from agents.loading.scenario_file import load_scenario
from deploy.recording.loop import MCAP_FILE, Recorder
from deploy.recording.progress import live_errors
from tests.recorder_synth import SynthRun
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import Stamper

START_S = 1_700_000_000.0


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--duration", type=float, default=200.0)
    parser.add_argument("--case", default="paper")
    args = parser.parse_args()
    scenario = load_scenario(args.case)
    keys = SwarmKeys("bench")
    run = SynthRun(scenario, keys, START_S, duration_s=args.duration, pre_s=0.0, post_s=0.0)
    with tempfile.TemporaryDirectory() as tmp, MemoryBus(MemoryHub(), "rec") as rbus:
        sbus = MemoryBus(rbus.hub, "swarm")
        recorder = Recorder(rbus, "bench", scenario, Path(tmp), period_s=1e9)
        sbus.publish(keys.control(), encode(run.control(Stamper("launcher-0"), "start")))
        per_batch = round(run.rate_hz) * (1 + scenario.n)
        batch: list[tuple[str, bytes]] = []
        handled, wall, cpu = 0, 0.0, 0.0

        def flush() -> None:
            nonlocal handled, wall, cpu
            for key, payload in batch:
                sbus.publish(key, payload)
            batch.clear()
            w0, c0 = time.perf_counter(), time.process_time()
            handled += recorder.step()
            backlog = getattr(recorder, "backlog", None)  # the tree before issue 50's
            while backlog:
                handled += recorder.step(drain=False)  # type: ignore[call-arg]
            wall += time.perf_counter() - w0
            cpu += time.process_time() - c0

        for key, msg in run.samples():
            batch.append((key, encode(msg)))
            if len(batch) == per_batch:
                flush()
        flush()
        t0 = time.perf_counter()
        live = live_errors(recorder.asm, dataclasses.replace(
            getattr(recorder, "info", None) or recorder._info,  # (the tree before issue 50's)
            steady_from_s=args.duration / 2))
        tick_ms = 1000 * (time.perf_counter() - t0)
        sbus.publish(keys.control(), encode(run.control(Stamper("launcher-0"), "stop")))
        recorder.step()
        in_loop_s = getattr(recorder, "decode_cpu_s", 0.0)
        t0 = time.perf_counter()
        ok = recorder.finish()
        final_s = time.perf_counter() - t0
        decode_s = getattr(recorder, "decode_cpu_s", 0.0)
        at_end_s = decode_s - in_loop_s
        size = (Path(tmp) / MCAP_FILE).stat().st_size
        sbus.close()
    print(f"recorder, {args.case} case ({scenario.n} followers), {args.duration:g} s at 50 Hz")
    print(f"  messages handled        {handled}")
    print(f"  loop throughput         {handled / wall:,.0f} msg/s "
          f"(swarm sends {per_batch} msg/s)")
    print(f"  CPU per message         {1e6 * cpu / handled:.1f} us")
    # States decoded late (deploy.recording.intake): the batch left for the end, too.
    print(f"  with the end's decoding {1e6 * (cpu + at_end_s) / handled:.1f} us "
          f"({at_end_s:.2f} s of deferred decoding at the end, "
          f"{1e6 * decode_s / handled:.1f} us/msg in all)")
    print(f"  progress errors tick    {tick_ms:.2f} ms  (max |e_rho| {live['max_abs_e_rho_m']})")
    print(f"  final outputs           {final_s:.2f} s  (metrics ok: {ok})")
    print(f"  MCAP size               {size / 1e6:.2f} MB ({size / handled:.0f} B/msg)")


if __name__ == "__main__":
    main()
