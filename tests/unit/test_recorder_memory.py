"""The recorder's memory does not grow with the run: what it keeps per message is on disk.

A Recorder on an in-memory bus is fed a synthetic run (truth, states and the followers'
link counters); the Python heap it holds (tracemalloc: numpy's arrays included) after 20 s
of run and after 80 s must be the same within a margin far below what keeping the messages
would cost (~600 B a message, 45 000 messages between the two readings).
"""

from __future__ import annotations

import gc
import tracemalloc
from pathlib import Path

import pytest

from agents.loading.scenario_file import load_scenario
from deploy.recording.loop import Recorder
from tests.recorder_synth import SynthRun
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import Header, ProcessStatus, Stamper, TruthSnapshot

START_S = 1_700_000_000.0
MARGIN_B = 1_000_000


def link_status(i: int, k: int, stamp_s: float) -> ProcessStatus:
    j = (i - 1) % 4
    counters = {f"rx_f{j}": 50 * k, f"seq_first_f{j}": 0, f"seq_last_f{j}": 50 * k,
                f"age_n_f{j}": 50 * k, f"age_sum_us_f{j}": 900_000 * k,
                "rx_sensor": 50 * k, "seq_first_sensor": 0, "seq_last_sensor": 50 * k}
    return ProcessStatus(Header(f"follower-{i}", k, stamp_s), "follower", i, "running",
                         counters, "")


@pytest.mark.timeout(180)
def test_recorder_heap_is_flat_over_the_run(tmp_path: Path) -> None:
    paper = load_scenario("paper")
    hub, keys = MemoryHub(), SwarmKeys("mem")
    run = SynthRun(paper, keys, START_S, duration_s=80.0, pre_s=0.0, post_s=0.0)
    readings: dict[float, int] = {}
    with MemoryBus(hub, "recorder") as rbus, MemoryBus(hub, "swarm") as sbus:
        recorder = Recorder(rbus, "mem", paper, tmp_path, period_s=1e9)
        sbus.publish(keys.control(), encode(run.control(Stamper("launcher-0"), "start")))
        tracemalloc.start()
        truths = 0
        try:
            for key, msg in run.samples():
                sbus.publish(key, encode(msg))
                truths += isinstance(msg, TruthSnapshot)
                if isinstance(msg, TruthSnapshot) and truths % round(run.rate_hz) == 1:
                    second = truths // round(run.rate_hz)
                    for i in range(paper.n):
                        sbus.publish(keys.status("follower", i),
                                     encode(link_status(i, second, msg.header.stamp_s)))
                    recorder.step()
                    if second in (20, 80):
                        gc.collect()
                        readings[second] = tracemalloc.get_traced_memory()[0]
        finally:
            tracemalloc.stop()
        assert recorder.asm.truth_count == 4001
        sbus.publish(keys.control(), encode(run.control(Stamper("launcher-0"), "stop")))
        recorder.step()
        assert recorder.finish()
    grown = readings[80] - readings[20]
    print(f"recorder heap: {readings[20] / 1e6:.2f} MB at 20 s, {readings[80] / 1e6:.2f} MB "
          f"at 80 s ({grown / 1e3:+.0f} kB)")
    assert grown < MARGIN_B
    assert (tmp_path / "series.parquet").is_file() and (tmp_path / "links.csv").is_file()
