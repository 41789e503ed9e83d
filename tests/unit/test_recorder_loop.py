"""The recorder loop on an in-memory bus: bad payloads counted not fatal, stop, outputs."""

from __future__ import annotations

import json
from pathlib import Path

import msgpack
import pytest
from mcap.reader import make_reader

from agents.loading.scenario_file import load_scenario
from agents.scenario.model import Scenario
from deploy.recording.loop import MCAP_FILE, Recorder
from deploy.recording.queues import (
    DRAIN_PIECE,
    DRAIN_PIECES_MAX,
    QUEUE_HOLD_S,
    QUEUE_MAX,
    queue_capacities,
)
from deploy.report.run_report import regenerate_figures
from tests.recorder_synth import SynthRun
from transport.bus import Received
from transport.codec import decode, encode
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import Header, ProcessStatus, Stamper

START_S = 1_700_000_000.0


@pytest.fixture(scope="module")
def paper() -> Scenario:
    return load_scenario("paper")


def topics(path: Path) -> dict[str, int]:
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    counts = summary.statistics.channel_message_counts
    return {c.topic: counts.get(c.id, 0) for c in summary.channels.values()}


@pytest.mark.timeout(60)
def test_garbage_is_counted_and_the_run_is_recorded(paper: Scenario, tmp_path: Path) -> None:
    hub, keys = MemoryHub(), SwarmKeys("loop")
    run = SynthRun(paper, keys, START_S, duration_s=1.0)
    with MemoryBus(hub, "recorder") as rbus, MemoryBus(hub, "swarm") as sbus:
        status = rbus.subscribe(keys.status("recorder", 0))
        recorder = Recorder(rbus, "loop", paper, tmp_path)
        first = decode(status.drain()[0].payload)
        assert isinstance(first, ProcessStatus) and first.state == "linked"
        control = Stamper("launcher-0")
        sbus.publish(keys.control(), encode(run.control(control, "start")))
        for i, (key, msg) in enumerate(run.samples()):
            sbus.publish(key, encode(msg))
            if i == 100:
                sbus.publish(keys.truth(), b"\xc1 garbage")
                sbus.publish(keys.follower_state(1), msgpack.packb([7, 1, "f", 0, 1.0]))
        sbus.publish(keys.control(), encode(run.control(control, "stop")))
        assert recorder.run(lambda: False, poll_s=0.0) == "control_stop"
        # The bad state is no state's wire array: not recorded; refused, and counted, when
        # its batch is decoded.
        assert dict(recorder.decoder.dropped) == {"msgpack": 1}
        assert recorder.finish()
        states = [decode(r.payload) for r in status.drain()]
    assert [s.state for s in states if isinstance(s, ProcessStatus)][-3:] == [
        "running", "stopping", "done"]
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    dropped = metrics["recorder"]["dropped"]
    assert dropped == {"msgpack": 1, "version": 1}
    assert metrics["samples"] == 51 and metrics["radius_error_m"] < 1e-9
    assert metrics["recorder"]["stop_reason"] == "control_stop"
    recorded = topics(tmp_path / MCAP_FILE)
    assert recorded[keys.truth()] == 71 and recorded[keys.follower_state(3)] == 71
    assert recorded[keys.follower_state(1)] == 71  # not the refused one
    assert metrics["recorder"]["deferred"]["decoded"] == 4 * 71 + 1
    assert recorded[keys.control()] == 2
    progress = json.loads((tmp_path / "progress.json").read_text())
    assert progress["state"] == "done" and progress["max_abs_e_rho_m"] < 1e-9
    # `enclose report` works on the recorder's run directory.
    for png in regenerate_figures(tmp_path):
        assert png.stat().st_size > 1000


@pytest.mark.timeout(60)
def test_no_truth_gives_error_metrics_and_keeps_the_mcap(
    paper: Scenario, tmp_path: Path
) -> None:
    hub, keys = MemoryHub(), SwarmKeys("empty")
    run = SynthRun(paper, keys, START_S)
    with MemoryBus(hub, "recorder") as rbus, MemoryBus(hub, "swarm") as sbus:
        recorder = Recorder(rbus, "empty", paper, tmp_path)
        sbus.publish(keys.control(), encode(run.control(Stamper("launcher-0"), "start")))
        sbus.publish(keys.control(), encode(run.control(Stamper("launcher-0"), "stop")))
        recorder.run(lambda: False, poll_s=0.0)
        assert not recorder.finish()
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert "no truth" in metrics["error"]
    assert topics(tmp_path / MCAP_FILE)[keys.control()] == 2
    assert not (tmp_path / "series.csv").exists()


@pytest.mark.realtime
@pytest.mark.timeout(30)
def test_signal_stops_the_loop(paper: Scenario, tmp_path: Path) -> None:
    with MemoryBus(MemoryHub(), "recorder") as rbus:
        recorder = Recorder(rbus, "sig", paper, tmp_path)
        calls = iter([False, False, True])
        assert recorder.run(lambda: next(calls), poll_s=0.0) == "signal"
        recorder.finish()
    assert (tmp_path / MCAP_FILE).stat().st_size > 0


@pytest.mark.timeout(60)
def test_membership_changes_become_phases_and_marks(paper: Scenario, tmp_path: Path) -> None:
    """Follower 4 (index 3) leaves 1 s into a 2-s run: two phases in metrics.json."""
    hub, keys = MemoryHub(), SwarmKeys("members")
    run = SynthRun(paper, keys, START_S, duration_s=2.0)
    clock = [START_S - 1.0]
    tokens = [MemoryBus(hub, f"f{i}").declare_token(keys.alive("follower", i)) for i in range(4)]
    with MemoryBus(hub, "recorder", clock=lambda: clock[0]) as rbus, \
            MemoryBus(hub, "swarm") as sbus:
        recorder = Recorder(rbus, "members", paper, tmp_path)
        control = Stamper("launcher-0", lambda: clock[0])  # checked against the bus clock
        sbus.publish(keys.control(), encode(run.control(control, "start")))
        for key, msg in run.samples():
            clock[0] = msg.header.stamp_s
            if clock[0] >= START_S + 1.0:
                tokens[3].close()  # as a SIGKILLed process's token goes (closing twice: no-op)
            sbus.publish(key, encode(msg))
            recorder.step()
        clock[0] += 0.1
        sbus.publish(keys.control(), encode(run.control(control, "stop")))
        assert recorder.run(lambda: False, poll_s=0.0) == "control_stop"
        assert recorder.finish()
    membership = json.loads((tmp_path / "metrics.json").read_text())["membership"]
    assert membership["changes_s"] == [pytest.approx(1.0, abs=0.03)]
    first, second = membership["phases"]
    assert first["members"] == [0, 1, 2, 3] and second["members"] == [0, 1, 2]
    assert first["reform_s"] == 0.0  # the synthetic ring is the planned one throughout


@pytest.mark.timeout(60)
def test_a_restarted_recorder_carries_on_the_runs_outputs(paper: Scenario, tmp_path: Path) -> None:
    """Recorder A dies half way (its MCAP flushed, never finished; the launcher renames it);
    recorder B reads it back, so the outputs cover the whole run, not just B's half."""
    hub, keys = MemoryHub(), SwarmKeys("resume")
    run = SynthRun(paper, keys, START_S, duration_s=2.0)
    samples = list(run.samples())
    half = len(samples) // 2
    control = Stamper("launcher-0")
    with MemoryBus(hub, "swarm") as sbus:
        with MemoryBus(hub, "recorder-a") as abus:
            dead = Recorder(abus, "resume", paper, tmp_path, chunk_bytes=2048)
            sbus.publish(keys.control(), encode(run.control(control, "start")))
            for key, msg in samples[:half]:
                sbus.publish(key, encode(msg))
            dead.step()
            dead.mcap.flush()  # what its loop does each second; then SIGKILL: no finish()
        (tmp_path / MCAP_FILE).rename(tmp_path / "recording-part1.mcap")
        with MemoryBus(hub, "recorder-b") as bbus:
            recorder = Recorder(bbus, "resume", paper, tmp_path)
            for key, msg in samples[half:]:
                sbus.publish(key, encode(msg))
            sbus.publish(keys.control(), encode(run.control(control, "stop")))
            assert recorder.run(lambda: False, poll_s=0.0) == "control_stop"
            assert recorder.finish()
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    carried = metrics["recorder"]["carried_on"]
    # A got the start word, half the samples and its own "linked" status; at most the chunk
    # it was building is lost (2 KiB: a handful of messages), and its file ends without a
    # summary.  Its live view's frames are carried too, bytes untouched.
    assert half + 2 - 10 <= carried["messages"] <= half + 2, carried
    assert carried["truncated_tail"] == 1
    assert carried["view_frames"] >= 1
    assert metrics["samples"] >= 101 - 5
    series = (tmp_path / "series.csv").read_text().splitlines()
    assert float(series[1].split(",")[0]) < 0.05  # starts with A's first second
    recorded = sum(topics(tmp_path / MCAP_FILE).values())
    # + the stop word, + the recorder's own status messages
    assert recorded >= carried["messages"] + len(samples) - half + 1


@pytest.mark.timeout(60)
@pytest.mark.parametrize("record_sensor", [True, False])
def test_target_observations_are_recorded_only_when_asked(
        paper: Scenario, tmp_path: Path, record_sensor: bool) -> None:
    """The launcher leaves noiseless observations out (`--no-sensor`): the truth holds them."""
    from transport.messages import TargetObservation

    hub, keys = MemoryHub(), SwarmKeys("obs")
    run = SynthRun(paper, keys, START_S, duration_s=1.0)
    with MemoryBus(hub, "recorder") as rbus, MemoryBus(hub, "swarm") as sbus:
        recorder = Recorder(rbus, "obs", paper, tmp_path, record_sensor=record_sensor)
        control = Stamper("launcher-0")
        sbus.publish(keys.control(), encode(run.control(control, "start")))
        seen = Stamper("sim-0")
        for key, msg in run.samples():
            sbus.publish(key, encode(msg))
        for i in range(paper.n):
            sbus.publish(keys.sensor_targets(i), encode(TargetObservation(
                seen.header(START_S + 0.5), i, 0, (1.0, 2.0), START_S + 0.5, None)))
        sbus.publish(keys.control(), encode(run.control(control, "stop")))
        assert recorder.run(lambda: False, poll_s=0.0) == "control_stop"
        assert recorder.finish()
    sensor_topics = {t for t in topics(tmp_path / MCAP_FILE) if "/sensor/" in t}
    assert (len(sensor_topics) == paper.n) if record_sensor else not sensor_topics
    assert keys.truth() in topics(tmp_path / MCAP_FILE)


@pytest.mark.timeout(30)
def test_a_recorder_behind_the_bus_says_by_how_much_and_calls_no_link_silent(
    paper: Scenario, tmp_path: Path
) -> None:
    """A saturated recorder drains the followers' statuses 5 s after they were sent: all
    links deliver, so none is silent; the lag is progress.json's "recorder_behind_s"
    (against the senders' stamps: its own status, stamped as it ticks, does not count)."""
    hub, keys, clock = MemoryHub(), SwarmKeys("behind"), [START_S + 5.3]
    with MemoryBus(hub, "recorder", clock=lambda: clock[0]) as rbus, \
            MemoryBus(hub, "swarm", clock=lambda: clock[0]) as sbus:
        recorder = Recorder(rbus, "behind", paper, tmp_path, scene_hz=None)
        assert recorder.progress()["recorder_behind_s"] is None  # nothing processed yet
        for i in range(4):
            counters = {f"rx_f{(i - 1) % 4}": 10, f"seq_last_f{(i - 1) % 4}": 9}
            status = ProcessStatus(Header(f"follower-{i}", 0, START_S + 0.1 * i), "follower",
                                   i, "running", counters)
            sbus.publish(keys.status("follower", i), encode(status))
        recorder.step()
        progress = recorder.progress()
        recorder.mcap.close()
    assert progress["links"]["count"] == 4 and progress["links"]["silent"] == []
    assert progress["recorder_behind_s"] == pytest.approx(5.0)


def publish_backlog(bus: MemoryBus, keys: SwarmKeys) -> int:
    """More statuses than a drain's piece, queued at once; how many."""
    count = DRAIN_PIECE + 7
    for k in range(count):
        status = ProcessStatus(Header("target-0", k, START_S), "target", 0, "running", {})
        bus.publish(keys.status("target", 0), encode(status))
    return count


@pytest.mark.timeout(30)
def test_a_step_takes_every_ring_whole_and_records_it(tmp_path: Path) -> None:
    ring64 = load_scenario("ring64")  # its statuses' queue holds the whole backlog
    hub, keys, clock = MemoryHub(), SwarmKeys("batch"), [START_S]
    with MemoryBus(hub, "recorder", clock=lambda: clock[0]) as rbus, \
            MemoryBus(hub, "swarm", clock=lambda: clock[0]) as sbus:
        recorder = Recorder(rbus, "batch", ring64, tmp_path, scene_hz=None)
        backlog = publish_backlog(sbus, keys)
        steps = [recorder.step() for _ in range(2)]
        recorder.mcap.close()
    assert steps[0] - backlog in (0, 1) and steps[1] == 0  # (and the recorder's own status)
    assert topics(tmp_path / MCAP_FILE)[keys.status("target", 0)] == backlog


@pytest.mark.realtime
@pytest.mark.timeout(30)
def test_a_worked_off_backlog_is_handed_back_once(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    trims: list[int] = []
    monkeypatch.setattr("deploy.recording.loop.trim_heap", lambda: trims.append(1))
    ring64, hub, keys = load_scenario("ring64"), MemoryHub(), SwarmKeys("trim")
    with MemoryBus(hub, "recorder", clock=lambda: START_S) as rbus, \
            MemoryBus(hub, "swarm", clock=lambda: START_S) as sbus:
        recorder = Recorder(rbus, "trim", ring64, tmp_path, scene_hz=None)
        publish_backlog(sbus, keys)
        loops = iter(range(6))
        recorder.final_status_wait_s = 0.0
        assert recorder.run(lambda: next(loops, 5) >= 5, poll_s=0.0) == "signal"
        recorder.mcap.close()
    assert trims == [1]  # after the backlog, not on every step


@pytest.mark.parametrize(("noise_std_m", "figures", "argv"), [
    (0.0, True, ["--no-sensor"]), (0.2, True, []), (0.2, False, ["--no-figures"])])
def test_the_launcher_records_observations_only_when_they_are_noisy_and_figures_if_asked(
        noise_std_m: float, figures: bool, argv: list[str]) -> None:
    from types import SimpleNamespace

    from deploy.launch.launch_options import LaunchOptions
    from deploy.launch.launcher import Launch

    opts = LaunchOptions(noise_std_m=noise_std_m, figures=figures)
    assert Launch.recorder_output_argv(SimpleNamespace(opts=opts)) == argv  # type: ignore[arg-type]
    # A launcher in a namespace (netns, hosts) is told the same.
    assert ("--no-figures" in opts.supervision_argv()) is not figures


@pytest.mark.timeout(30)
@pytest.mark.parametrize("name", ["paper", "ring16", "ring64"])
@pytest.mark.parametrize("sensor", [True, False])
def test_each_queue_holds_its_keys_traffic_and_no_more(name: str, sensor: bool) -> None:
    # A ring's pages are mapped as its writer first passes them: one far larger than its
    # key's traffic is memory creeping up for as long as a lap takes.
    scenario, keys = load_scenario(name), SwarmKeys("q")
    sizes = queue_capacities(keys, scenario, sensor)
    assert list(sizes) == list(keys.recorded(sensor))
    states_per_s = scenario.n * scenario.run.rate_hz
    states = sizes[keys.all_follower_states()]
    assert states >= min(QUEUE_MAX, states_per_s * QUEUE_HOLD_S)
    assert states < max(QUEUE_MAX, 2 * states_per_s * QUEUE_HOLD_S)
    statuses_per_s = scenario.n + scenario.m + 3  # with the simulator, recorder, launcher
    statuses = sizes[keys.all_status()]
    assert statuses_per_s * QUEUE_HOLD_S <= statuses <= 2 * (statuses_per_s + 1) * QUEUE_HOLD_S
    assert sizes[keys.control()] <= 256 and sizes[keys.all_alive()] <= 256
    assert (keys.all_sensor_targets() in sizes) is sensor


class _Flood:
    """A subscription a flood refills as fast as it is drained: garbage, every time."""

    def __init__(self, key_expr: str) -> None:
        self.key_expr, self.drained = key_expr, 0

    def drain(self, max_items: int | None = None) -> list[Received]:
        n = max_items or 1
        self.drained += n
        return [Received(self.key_expr, b"\xc1", 0.0) for _ in range(n)]

    def close(self) -> None:
        pass


@pytest.mark.timeout(60)
def test_a_flood_cannot_hold_a_step_or_the_stop(tmp_path: Path) -> None:
    hub = MemoryHub()
    with MemoryBus(hub, "recorder") as rbus:
        recorder = Recorder(rbus, "flood", load_scenario("paper"), tmp_path, scene_hz=None)
        flood = _Flood(recorder._subs[0].key_expr)
        recorder._subs = [flood]
        assert recorder.step() == DRAIN_PIECES_MAX * DRAIN_PIECE  # a full ring's worth at most
        assert flood.drained == DRAIN_PIECES_MAX * DRAIN_PIECE
        # Its key is no process's: refused before decoding, counted, never recorded.
        assert recorder.decoder.dropped == {"unknown_key": DRAIN_PIECES_MAX * DRAIN_PIECE}
        recorder.mcap.close()
    assert not topics(tmp_path / MCAP_FILE)
