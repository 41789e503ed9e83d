"""metrics.json "links": the followers' final counters, and the recorder's wait for them."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from agents.loading.scenario_file import load_scenario
from deploy.recording.links import link_report, unreadable_links
from deploy.recording.loop import Recorder
from tests.recorder_synth import SynthRun
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import Header, ProcessStatus, Stamper

START_S = 1_700_000_000.0


def status(i: int, state: str, **counters: int) -> ProcessStatus:
    return ProcessStatus(Header(f"follower-{i}", 0, START_S), "follower", i, state, counters)


def test_link_report_ratios_ages_and_sources() -> None:
    statuses = {
        1: status(1, "done", rx_f0=80, rx_dup_f0=3, age_p50_us_f0=52_300, age_p99_us_f0=71_000,
                  imp_offered_f0=100, imp_dropped_f0=20, rx_sensor=45, seq_first_sensor=10,
                  seq_last_sensor=69, states_sent=90),
        0: status(0, "running", rx_f1=90, states_sent=100),
    }
    links = link_report(statuses, recorded_states=[100, 95])
    assert set(links) == {"f0->f1", "sensor->f1", "f1->f0"}
    f01 = links["f0->f1"]
    assert f01["delivered_ratio"] == pytest.approx(0.8) and f01["sent_source"] == "states_sent"
    assert f01["age_p50_ms"] == pytest.approx(52.3) and f01["age_p99_ms"] == pytest.approx(71.0)
    assert f01["duplicates"] == 3 and f01["impairment"] == {"offered": 100, "dropped": 20}
    assert f01["final"] is True and links["f1->f0"]["final"] is False
    assert links["f1->f0"]["delivered_ratio"] == pytest.approx(1.0)  # follower 1's states_sent
    sensor = links["sensor->f1"]
    assert sensor["sent"] == 60 and sensor["sent_source"] == "seq_span"
    assert sensor["delivered_ratio"] == pytest.approx(0.75) and sensor["age_p50_ms"] is None
    # Without the sender's own count, the recorder's is used.
    links = link_report({1: status(1, "done", rx_f0=76)}, recorded_states=[95, 0])
    assert links["f0->f1"]["sent"] == 95 and links["f0->f1"]["sent_source"] == "recorder"


@pytest.mark.realtime
@pytest.mark.timeout(60)
def test_recorder_waits_boundedly_for_final_statuses_and_reports_links(tmp_path: Path) -> None:
    paper, keys = load_scenario("paper"), SwarmKeys("links")
    run = SynthRun(paper, keys, START_S, duration_s=1.0)
    with MemoryBus(MemoryHub(), "recorder") as rbus:
        sbus = MemoryBus(rbus.hub, "swarm")
        recorder = Recorder(rbus, "links", paper, tmp_path, final_status_wait_s=0.5)
        control = Stamper("launcher-0")
        sbus.publish(keys.control(), encode(run.control(control, "start")))
        for key, msg in run.samples():
            sbus.publish(key, encode(msg))
        for i in range(3):
            counters = {f"rx_f{(i + 1) % 4}": 60, "states_sent": 71}
            sbus.publish(keys.status("follower", i), encode(status(i, "done", **counters)))
        sbus.publish(keys.status("follower", 3), encode(status(3, "running", rx_f0=70)))
        sbus.publish(keys.control(), encode(run.control(control, "stop")))
        t0 = time.monotonic()
        assert recorder.run(lambda: False, poll_s=0.01) == "control_stop"
        waited_s = time.monotonic() - t0
        assert recorder.finish()
        sbus.close()
    assert 0.5 <= waited_s < 3.0  # follower 3 never said "done"
    links = json.loads((tmp_path / "metrics.json").read_text())["links"]
    assert links["f1->f0"]["delivered_ratio"] == pytest.approx(60 / 71)
    assert links["f0->f3"]["sent_source"] == "states_sent" and links["f0->f3"]["final"] is False
    assert links["f3->f2"]["sent"] == 71 and links["f3->f2"]["sent_source"] == "recorder"


@pytest.mark.realtime
@pytest.mark.timeout(30)
def test_no_wait_when_every_follower_is_done(tmp_path: Path) -> None:
    paper, keys = load_scenario("paper"), SwarmKeys("done")
    with MemoryBus(MemoryHub(), "recorder") as rbus:
        sbus = MemoryBus(rbus.hub, "swarm")
        recorder = Recorder(rbus, "done", paper, tmp_path, final_status_wait_s=20.0)
        for i in range(paper.n):
            sbus.publish(keys.status("follower", i), encode(status(i, "done", states_sent=1)))
        calls = iter([False, True])
        t0 = time.monotonic()
        assert recorder.run(lambda: next(calls), poll_s=0.0) == "signal"
        assert time.monotonic() - t0 < 5.0
        assert sorted(recorder.follower_status) == list(range(paper.n))
        recorder.finish()
        sbus.close()


def test_rx_counters_that_name_no_link_are_skipped_and_counted() -> None:
    odd = status(1, "done", rx_f0=80, rx_fx=1, rx_f=2, rx_g3=3, **{"rx_f\u0663": 4,
                 "rx_f\u00b2": 5, "rx_": 6}, states_sent=90)
    statuses = {1: odd, 0: status(0, "done", rx_f1=90, states_sent=100)}
    links = link_report(statuses, recorded_states=[100, 95])
    assert set(links) == {"f0->f1", "f1->f0"}
    assert unreadable_links(statuses) == 6
