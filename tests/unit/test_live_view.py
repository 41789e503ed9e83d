"""The live view: messages to scene and plot frames, link health, the server, its options."""

from __future__ import annotations

import argparse
import json
import math
import socket
from pathlib import Path
from typing import Any

import pytest
from foxglove import messages as fm

from agents.loading.scenario_file import load_scenario
from agents.scenario.model import Scenario
from deploy.launch import live_args
from deploy.recording.live_links import LinkTracker, health
from deploy.recording.live_server import LiveServer, is_loopback
from deploy.recording.scene import (
    CIRCLE_SEGMENTS,
    HEALTH_RGBA,
    LinkView,
    centre_m,
    scene_update,
    timestamp,
)
from deploy.recording.view import (
    ERRORS_TOPIC,
    LINKS_TOPIC,
    LOG_TOPIC,
    SCENE_TOPIC,
    SCHEMAS,
    STATUS_TOPIC,
    LiveView,
    errors_now,
)
from deploy.report.rundir import RunInfo
from errors import DeployError
from tests.foxglove_client import foxglove_client, protobuf_class
from tests.recorder_synth import SynthRun
from transport.key_exprs import SwarmKeys
from transport.messages import FollowerState, Header, ProcessStatus, TruthSnapshot

START_S = 1_700_000_000.0


@pytest.fixture(scope="module")
def paper() -> Scenario:
    return load_scenario("paper")


def info(scenario: Scenario) -> RunInfo:
    return RunInfo.from_scenario(scenario, "networked", 10.0)


def truth(stamp_s: float = START_S + 0.25) -> TruthSnapshot:
    pos = ((1.0, 2.0, 10.0), (3.0, -4.0, 11.0), (0.0, 0.0, 9.0), (-5.0, 1.0, 10.0))
    return TruthSnapshot(Header("sim-0", 0, stamp_s), 0.0, pos, ((0.0,) * 3,) * 4,
                         ((0.0, 0.0), (2.0, 2.0)), ((0.0, 0.0),) * 2)


def state(i: int, r_m: tuple[float, float], stamp_s: float = START_S) -> FollowerState:
    z = (0.0, 0.0)
    return FollowerState(Header(f"follower-{i}", 0, stamp_s), i, r_m, (1.0, 0.0), z, z, z, 0.0)


def entities(update: fm.SceneUpdate) -> dict[str, Any]:
    """The update's entities by id, as a Foxglove client decodes them (google.protobuf)."""
    schema = fm.SceneUpdate.get_schema()
    decoded = protobuf_class(schema.name, bytes(schema.data)).FromString(update.encode())
    return {e.id: e for e in decoded.entities}


@pytest.mark.timeout(30)
def test_scene_puts_vehicles_targets_estimates_and_circle_where_the_messages_say() -> None:
    t = truth()
    update = scene_update(t, {2: state(2, (0.5, 0.7))}, [], rho_d_m=8.0)
    got = entities(update)
    for i, (x, y, z) in enumerate(t.follower_pos_m):
        p = got[f"follower-{i}"].spheres[0].pose.position
        assert (p.x, p.y, p.z) == (x, y, z)
        assert got[f"follower-{i}"].frame_id == "world"
    cube = got["target-1"].cubes[0].pose.position
    assert (cube.x, cube.y, cube.z) == (2.0, 2.0, 0.0)
    est = got["estimate-2"].spheres[0].pose.position
    assert (est.x, est.y) == (0.5, 0.7) and "estimate-0" not in got
    assert centre_m(t) == (1.0, 1.0)
    circle = got["circle"].lines[0].points
    assert len(circle) == CIRCLE_SEGMENTS + 1
    assert all(math.isclose(math.hypot(p.x - 1.0, p.y - 1.0), 8.0) for p in circle)
    assert all(p.z == 10.0 for p in circle)  # the vehicles' mean altitude
    stamp = got["follower-0"].timestamp
    assert stamp.seconds + stamp.nanos * 1e-9 == pytest.approx(START_S + 0.25, abs=1e-6)


@pytest.mark.timeout(30)
def test_links_are_drawn_beside_each_other_in_their_health_colours() -> None:
    links = [LinkView(0, 1, "good"), LinkView(1, 0, "bad"), LinkView(7, 0, "good")]
    line = entities(scene_update(truth(), {}, links, 8.0))["links"].lines[0]
    assert len(line.points) == 4  # the link from follower 7 (none) is left out
    assert line.colors[0].g == HEALTH_RGBA["good"][1] and line.colors[2].r == 0.9
    # Both directions of 0 <-> 1 are parallel, offset to either side.
    there = (line.points[0].x, line.points[0].y)
    back = (line.points[3].x, line.points[3].y)
    assert there != back and math.dist(there, back) == pytest.approx(0.5)


@pytest.mark.timeout(30)
def test_timestamp_splits_seconds_and_nanoseconds() -> None:
    ts = timestamp(12.5)
    assert (ts.sec, ts.nsec) == (12, 500_000_000)
    assert timestamp(-3.0).sec == 0


@pytest.mark.timeout(30)
def test_errors_of_a_perfect_formation_are_zero_and_carry_the_bounds(paper: Scenario) -> None:
    run = SynthRun(paper, SwarmKeys("v"), START_S, duration_s=1.0)
    view_info = info(paper)
    states: dict[int, FollowerState] = {}
    last = None
    for _key, msg in run.samples():
        if isinstance(msg, FollowerState):
            states[msg.index] = msg
        elif isinstance(msg, TruthSnapshot):
            last = msg
    assert last is not None
    errors = errors_now(last, states, view_info)
    assert errors is not None
    assert errors["max_abs_e_rho_m"] < 1e-6 and errors["max_abs_e_delta"] < 1e-6
    assert errors["max_estimator_error_m"] < 1e-6
    assert (errors["bound_rho_m"], errors["bound_delta"]) == (0.0999, 0.0199)
    assert errors_now(last, {0: states[0]}, view_info) is None  # not every follower yet


@pytest.mark.timeout(30)
def test_view_throttles_the_scene_and_logs_state_changes(paper: Scenario) -> None:
    view = LiveView(info(paper), scene_hz=10.0)
    run = SynthRun(paper, SwarmKeys("v"), START_S, duration_s=1.0)
    shown, truths = [], []
    for _key, msg in run.samples():  # 50 Hz truth, one sample at a time
        view.add(msg, msg.header.stamp_s)
        shown += view.frames()
        if isinstance(msg, TruthSnapshot):
            truths.append(msg.header.stamp_s)
    scenes = [f for f in shown if f.topic == SCENE_TOPIC]
    expected = (truths[-1] - truths[0]) * 10.0  # at 10 Hz, of 50 Hz truth
    assert expected - 1 <= len(scenes) <= expected + 2, (len(scenes), len(truths))
    assert sum(f.topic == ERRORS_TOPIC for f in shown) >= len(scenes) - 1
    view.add(ProcessStatus(Header("follower-1", 0, START_S), "follower", 1, "failed",
                           {}, "boom"), START_S)
    frames = view.tick_frames(START_S + 1.0, frozenset({0, 2, 3}))
    logs = [f.data for f in frames if f.topic == LOG_TOPIC]
    assert len(logs) == 2  # follower-1 failed, and the member set
    assert b"follower-1 failed (boom)" in logs[0] and b"members [0, 2, 3]" in logs[1]
    status = json.loads(next(f.data for f in frames if f.topic == STATUS_TOPIC))
    assert status["members"] == [0, 2, 3]
    assert status["processes"] == [{"name": "follower-1", "state": "failed", "detail": "boom"}]
    assert status["refused"] == {}
    assert json.loads(next(f.data for f in frames if f.topic == LINKS_TOPIC)) == {"links": []}
    view.add(ProcessStatus(Header("recorder-0", 0, START_S), "recorder", 0, "running",
                           {"statuses_rejected": 7, "tokens_rejected": 2,
                            "rejected_from_follower-2": 7}), START_S)
    frames = view.tick_frames(START_S + 2.0, frozenset({0, 2, 3}))
    status = json.loads(next(f.data for f in frames if f.topic == STATUS_TOPIC))
    assert status["refused"] == {"statuses": 7, "tokens": 2, "from": {"follower-2": 7},
                                 "seen_by": {"follower-2": 1}}


def status(i: int, counters: dict[str, int], seq: int = 0) -> ProcessStatus:
    return ProcessStatus(Header(f"follower-{i}", seq, START_S), "follower", i, "running",
                         counters)


@pytest.mark.timeout(30)
def test_link_health_uses_the_window_between_the_receivers_statuses() -> None:
    tracker = LinkTracker()
    base = {"rx_f0": 100, "seq_last_f0": 99, "seq_first_f0": 0, "age_p50_us_f0": 20_000,
            "age_p99_us_f0": 60_000, "rx_sensor": 5, "seq_first_sensor": 0,
            "seq_last_sensor": 4}
    tracker.update(status(1, base), {}, [100, 100])
    first = {k.name: k for k in tracker.links()}
    assert first["f0->f1"].window_delivered_ratio is None and first["f0->f1"].health == "bad"
    assert first["f0->f1"].age_p50_ms == 20.0 and first["sensor->f1"].sender is None
    # 50 new sequence numbers, 30 of them delivered: 0.6, "degraded".
    tracker.update(status(1, {**base, "rx_f0": 130, "seq_last_f0": 149}, 1), {}, [150, 150])
    link = {k.name: k for k in tracker.links()}["f0->f1"]
    assert link.window_delivered_ratio == pytest.approx(0.6) and link.health == "degraded"
    assert link.sender == 0 and link.receiver == 1 and link.rx == 130


@pytest.mark.parametrize(("ratio", "age_ms", "expected"), [
    (1.0, 20.0, "good"), (0.95, None, "good"), (0.8, 20.0, "degraded"),
    (1.0, 200.0, "degraded"), (0.4, 20.0, "bad"), (1.0, 900.0, "bad"), (None, 20.0, "bad"),
])
def test_health_thresholds(ratio: float | None, age_ms: float | None, expected: str) -> None:
    assert health(ratio, age_ms) == expected


@pytest.mark.realtime
@pytest.mark.timeout(30)
def test_server_takes_the_next_free_port_and_a_real_client_decodes_the_scene() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        taken = busy.getsockname()[1]
        live = LiveServer("127.0.0.1", taken)
        try:
            assert live.port != taken and live.url == f"ws://127.0.0.1:{live.port}"
            view = LiveView(info(load_scenario("paper")))
            view.add(truth(), START_S + 0.3)
            (scene,) = view.frames()
            with foxglove_client(live.url) as client:
                live.publish(scene)  # advertised on its first frame
                client.wait_channels({SCENE_TOPIC}, 10.0)
                client.subscribe([SCENE_TOPIC])
                received: list = []
                for _ in range(50):  # the subscription takes a moment to reach the server
                    live.publish(scene)
                    received = client.receive(1, 0.2)
                    if received:
                        break
                assert received and received[0].payload == scene.data
                assert received[0].log_time_ns == scene.log_time_ns
                decoded = client.protobuf_class(SCENE_TOPIC).FromString(received[0].payload)
                pos = {e.id: e for e in decoded.entities}["follower-1"].spheres[0].pose.position
                assert (pos.x, pos.y, pos.z) == (3.0, -4.0, 11.0)
        finally:
            live.stop()


@pytest.mark.timeout(30)
def test_server_refuses_a_bad_port_and_knows_loopback() -> None:
    with pytest.raises(DeployError, match="70000"):
        LiveServer("127.0.0.1", 70000)
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.2")


@pytest.mark.timeout(30)
def test_launcher_options_url_and_port_pinning(tmp_path: Path) -> None:
    parser = argparse.ArgumentParser()
    live_args.add_live_arguments(parser)
    on = live_args.LiveOptions.from_namespace(parser.parse_args([]))
    off = live_args.LiveOptions.from_namespace(parser.parse_args(["--no-live"]))
    assert live_args.recorder_live_argv(on) == ["--live-port", "8765", "--live-host", "127.0.0.1"]
    assert off is None and live_args.recorder_live_argv(off) == []
    assert live_args.announce_live_url(off, tmp_path) is None
    (tmp_path / "progress.json").write_text(json.dumps({"live_url": "ws://127.0.0.1:8770"}))
    assert live_args.read_live_url(tmp_path, wait_s=0.0) == "ws://127.0.0.1:8770"
    argv = ["-m", "deploy.recording.recorder", "--live-port", "8765", "--live-host", "127.0.0.1"]
    live_args.pin_live_port(argv, "ws://127.0.0.1:8770")
    assert argv[3] == "8770"
    assert live_args.read_live_url(tmp_path / "none", wait_s=0.0) is None


LAYOUT = Path(__file__).resolve().parents[2] / "docs" / "foxglove-layout.json"


def _panel_paths(config: dict[str, Any]) -> list[str]:
    paths = [p["value"] for p in config.get("paths", [])]
    paths += [config[k] for k in ("topicPath", "topicToRender") if config.get(k)]
    paths += list(config.get("topics", {}))
    return paths


@pytest.mark.timeout(30)
def test_shipped_layout_shows_only_what_the_view_publishes() -> None:
    layout = json.loads(LAYOUT.read_text())
    panels = layout["configById"]
    errors_fields = json.loads(SCHEMAS[ERRORS_TOPIC].data)["properties"]
    for panel_id, config in panels.items():
        for path in _panel_paths(config):
            topic, _, field = path.partition(".")
            assert topic in SCHEMAS, (panel_id, path)
            if topic == ERRORS_TOPIC:
                assert field in errors_fields, (panel_id, path)
    used = set(json.dumps(layout["layout"]).replace('"', " ").split())
    assert set(panels) <= used  # every panel is placed
