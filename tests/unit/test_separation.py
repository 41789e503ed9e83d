"""The closest approach of two vehicles, and the metrics of a network fault's window."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from agents.analysis.metrics import (
    ErrorSeries,
    compute_metrics,
    separation_series,
    window_metrics,
)
from agents.analysis.timeseries import RunSeries
from agents.loading.scenario_file import load_scenario
from deploy.recording.scene import FOLLOWER_RGBA, TOO_CLOSE_RGBA, scene_update, too_close
from deploy.recording.view import ERRORS_TOPIC, LOG_TOPIC, SCENE_TOPIC, LiveView
from deploy.report.rundir import RunInfo
from deploy.report.verdict import read_verdict
from tests.unit.test_live_view import START_S, entities, state
from transport.messages import Header, RunControl, TruthSnapshot

pytestmark = pytest.mark.timeout(30)


def crossing_series() -> RunSeries:
    """Two vehicles meet at t = 5 s (0.2 m apart), a third stays 10 m away."""
    t = np.linspace(0.0, 10.0, 101)
    pos = np.zeros((len(t), 3, 2))
    pos[:, 0, 0] = t - 5.0
    pos[:, 1, 0] = 5.0 - t
    pos[:, 1, 1] = 0.2
    pos[:, 2, 1] = 10.0
    zeros = np.zeros_like(pos)
    return RunSeries(t, pos, zeros, zeros, np.zeros((len(t), 1, 2)))


def flat_errors(k: int, n: int, bad: slice = slice(0, 0)) -> ErrorSeries:
    e = np.zeros((k, n))
    e[bad] = 0.5
    return ErrorSeries(e, e, e, e, e)


def test_the_closest_pair_and_its_time() -> None:
    series = crossing_series()
    sep = separation_series(series.follower_pos_m)
    assert sep.shape == (101,)
    assert sep[50] == pytest.approx(0.2)
    assert int(np.argmin(sep)) == 50
    assert sep[0] == pytest.approx(np.hypot(10.0, 0.2))


def test_nan_positions_are_ignored() -> None:
    pos = np.array([[[0.0, 0.0], [3.0, 4.0], [np.nan, np.nan]],
                    [[np.nan, 0.0], [np.nan, 1.0], [0.0, 0.0]]])
    sep = separation_series(pos)
    assert sep[0] == pytest.approx(5.0)
    assert np.isnan(sep[1])


def test_metrics_give_the_closest_approach_per_phase() -> None:
    series = crossing_series()
    m = compute_metrics(series, flat_errors(101, 3), 7.0, 0.1, 0.02)
    assert m.min_separation_m == pytest.approx(0.2)
    assert m.min_separation_transient_m == pytest.approx(0.2)
    assert m.min_separation_steady_m == pytest.approx(np.hypot(4.0, 0.2))


def test_a_window_reports_its_worst_errors_and_recovery() -> None:
    series = crossing_series()  # samples every 0.1 s
    errors = flat_errors(101, 3, slice(40, 62))  # outside the bounds 4.0 .. 6.1 s
    w = window_metrics(series, errors, (3.0, 5.0), 0.1, 0.02)
    assert w["radius_error_m"] == pytest.approx(0.5)
    assert w["min_separation_m"] == pytest.approx(np.hypot(0.2, 0.2))  # at 4.9 s, the last
    assert w["recovery_s"] == pytest.approx(1.2)  # inside again from 6.2 s
    quiet = window_metrics(series, errors, (7.0, 8.0), 0.1, 0.02)
    assert quiet["recovery_s"] == 0.0 and quiet["radius_error_m"] == 0.0


def test_the_verdict_fails_a_near_collision_and_names_the_faults(tmp_path: Path) -> None:
    metrics = {"estimator_error_m": 0.01, "radius_error_m": 0.01, "angle_error": 0.001,
               "min_separation_m": 0.4,
               "net_faults": [{"label": "partition 1,2|3,4 40-55 s", "recovery_s": 3.25,
                               "min_separation_m": 0.4}]}
    (tmp_path / "metrics.json").write_text(json.dumps(metrics))
    (tmp_path / "run.json").write_text(json.dumps({"safety_distance_m": 0.5}))
    v = read_verdict(tmp_path, "run")
    sep = next(c for c in v.checks if c.key == "min_separation_m")
    assert not sep.inside and not v.inside
    assert v.network == ("partition 1,2|3,4 40-55 s: back inside the bounds 3.2 s after, "
                         "closest approach 0.40 m",)
    metrics["min_separation_m"] = 0.6
    (tmp_path / "metrics.json").write_text(json.dumps(metrics))
    assert read_verdict(tmp_path, "run").inside


def test_the_live_view_marks_vehicles_under_the_safety_distance_red() -> None:
    view = LiveView(RunInfo.from_scenario(load_scenario("paper"), "networked", 10.0))
    pos = ((0.0, 0.0, 10.0), (0.6, 0.0, 10.0), (10.0, 0.0, 10.0), (-10.0, 0.0, 10.0))
    snap = TruthSnapshot(Header("sim-0", 0, START_S), 0.0, pos, ((0.0,) * 3,) * 4,
                         ((0.0, 0.0), (2.0, 2.0)), ((0.0, 0.0),) * 2)
    for i in range(4):
        view.add(state(i, (1.0, 1.0)), START_S)
    view.add(snap, START_S)
    frames = view.frames()
    assert any(f.topic == SCENE_TOPIC for f in frames)
    pairs = too_close(snap, 1.0)
    assert [(i, j) for _, i, j in pairs] == [(0, 1)]
    drawn = entities(scene_update(snap, {}, [], 5.0, frozenset({0, 1})))
    red = {k for k, e in drawn.items() if k.startswith("follower-")
           and round(e.spheres[0].color.r, 2) == TOO_CLOSE_RGBA[0]}
    assert red == {"follower-0", "follower-1"} and FOLLOWER_RGBA[0] != TOO_CLOSE_RGBA[0]
    errors = json.loads(next(f.data for f in frames if f.topic == ERRORS_TOPIC))
    assert errors["min_separation_m"] == pytest.approx(0.6)
    assert errors["safety_distance_m"] == 1.0
    logs = [f.data for f in view.frames() if f.topic == LOG_TOPIC]
    assert len(logs) == 1 and b"followers 0 and 1 0.60 m apart" in logs[0]


def test_the_live_view_logs_each_network_fault_window() -> None:
    info = dataclasses.replace(RunInfo.from_scenario(load_scenario("paper"), "networked", 10.0),
                               net_faults=(("isolate 2 2-4 s", 2.0, 4.0),))
    view = LiveView(info)
    view.add(RunControl(Header("launcher-0", 0, START_S), "start", START_S, 10.0), START_S)
    said = []
    for k in range(12):
        frames = view.tick_frames(START_S + 0.5 * k, None)
        said += [(0.5 * k, f.data) for f in frames if f.topic == LOG_TOPIC]
    assert [t for t, _ in said] == [2.0, 4.0]
    assert b"network fault isolate 2 2-4 s begins" in said[0][1]
    assert b"ends" in said[1][1]
