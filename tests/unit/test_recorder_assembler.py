"""RunAssembler on synthetic message streams: alignment, window, fills, gaps, metrics."""

from __future__ import annotations

import dataclasses
import json
import random
from pathlib import Path

import numpy as np
import pytest

from agents.analysis.metrics import worst
from agents.analysis.timeseries import RunSeries
from agents.loading.scenario_file import load_scenario
from agents.scenario.model import Scenario
from deploy.recording.assembler import RunAssembler, align_latest
from deploy.recording.outputs import write_final_outputs
from deploy.recording.progress import live_errors
from deploy.report.run_report import write_run_outputs
from deploy.report.rundir import RunInfo
from errors import DeployError
from tests.recorder_synth import SynthRun, formation_m, lap_m, targets_m
from transport.key_exprs import SwarmKeys
from transport.messages import FollowerState, Header, Stamper, TruthSnapshot

START_S = 1_700_000_000.0


@pytest.fixture(scope="module")
def paper() -> Scenario:
    return load_scenario("paper")


def fed(scenario: Scenario, run: SynthRun, shuffle: bool = False) -> RunAssembler:
    asm = RunAssembler(scenario.n, scenario.m)
    msgs = [msg for _, msg in run.samples()]
    if shuffle:
        random.Random(7).shuffle(msgs)
    asm.add(run.control(Stamper("launcher-0"), "start"))
    for msg in msgs:
        asm.add(msg)
    return asm


def test_worst_ignores_nan_unless_all_is_nan() -> None:
    assert worst(np.array([0.1, np.nan, 0.3])) == 0.3
    assert np.isnan(worst(np.array([np.nan, np.nan])))
    assert worst(np.array([0.1, np.inf])) == np.inf  # only NaN means "no data"


def test_align_latest_picks_latest_not_after_and_flags_before_first() -> None:
    idx, filled = align_latest(np.array([0.5, 1.0, 1.5, 3.0]), np.array([1.0, 2.0]))
    assert idx.tolist() == [0, 0, 0, 1]
    assert filled.tolist() == [True, False, False, False]


def test_series_on_truth_grid_within_start_and_duration(paper: Scenario) -> None:
    run = SynthRun(paper, SwarmKeys("u"), START_S, duration_s=2.0, pre_s=0.3, post_s=0.3)
    asm = fed(paper, run)
    out = asm.build()
    t = out.series.t_s
    assert len(t) == 101 and t[0] == pytest.approx(0.0) and t[-1] == pytest.approx(2.0)
    assert np.allclose(np.diff(t), 0.02, atol=1e-6)  # float64 stamps: ulp 0.24 us
    assert out.start_source == "control" and out.duration_s == 2.0
    k = 37
    assert np.allclose(out.series.follower_pos_m[k], formation_m(paper, t[k]))
    assert np.allclose(out.series.target_pos_m[k], targets_m(paper, t[k]))
    # Estimate = the state stamped 4 ms before the truth sample, not the later one.
    # r_i is carried from its stamp to the truth's with dr_i: exact for this linear LAP.
    assert np.allclose(out.series.estimate_m[k], lap_m(t[k]))
    for f in out.followers:
        assert f.filled_samples == 0 and f.seq_gaps == 0 and f.stale == 0
        assert f.age_p50_ms == pytest.approx(4.0, abs=1e-3)
        assert f.age_p99_ms == pytest.approx(4.0, abs=1e-3)


def test_arrival_order_does_not_matter_only_stamps(paper: Scenario) -> None:
    run = SynthRun(paper, SwarmKeys("u"), START_S)
    ordered, shuffled = fed(paper, run).build(), fed(paper, run, shuffle=True).build()
    for name in ("t_s", "follower_pos_m", "estimate_m", "command_m_s", "target_pos_m"):
        assert np.array_equal(getattr(ordered.series, name), getattr(shuffled.series, name))


def test_first_state_fills_samples_before_it_and_is_counted(paper: Scenario) -> None:
    run = SynthRun(paper, SwarmKeys("u"), START_S, pre_s=0.0)
    asm = RunAssembler(paper.n, paper.m)
    asm.add(run.control(Stamper("launcher-0"), "start"))
    late_from = START_S + 0.5
    first_late: FollowerState | None = None
    for _, msg in run.samples():
        if isinstance(msg, FollowerState) and msg.index == 2 and msg.header.stamp_s < late_from:
            continue
        if isinstance(msg, FollowerState) and msg.index == 2 and first_late is None:
            first_late = msg
        asm.add(msg)
    out = asm.build()
    assert first_late is not None
    before = out.series.t_s + START_S < first_late.header.stamp_s
    assert out.followers[2].filled_samples == int(before.sum()) == 26
    assert out.filled_samples == 26 and out.followers[0].filled_samples == 0
    assert not np.isnan(out.series.estimate_m).any()
    assert np.allclose(out.series.estimate_m[before, 2], first_late.r_m)


def test_sequence_gaps_and_stale_states_counted_per_follower(paper: Scenario) -> None:
    asm = RunAssembler(paper.n, paper.m)
    asm.add(SynthRun(paper, SwarmKeys("u"), START_S).control(Stamper("l"), "start"))
    zero = (0.0, 0.0)

    def state(seq: int, stamp: float) -> FollowerState:
        return FollowerState(Header("follower-1", seq, stamp), 1, (float(seq), 0.0), zero,
                             zero, zero, zero, stamp)

    for seq in (0, 1, 2, 5, 6, 6, 4, 10):  # gaps 3-4 (2) and 7-9 (3); 6 again and 4: stale
        asm.add(state(seq, START_S + 0.01 * seq))
    log = asm.tallies[1]
    assert (log.gaps, log.stale) == (5, 2)
    assert asm.state_counts()[1] == 8


def test_truth_of_the_wrong_shape_and_bad_index_dropped(paper: Scenario) -> None:
    asm = RunAssembler(paper.n, paper.m)
    asm.add(TruthSnapshot(Header("sim-0", 0, START_S), 0.0, ((0.0, 0.0, 0.0),), (), (), ()))
    zero = (0.0, 0.0)
    asm.add(FollowerState(Header("follower-9", 0, START_S), 9, zero, zero, zero, zero, zero,
                          START_S))
    asm.add(FollowerState(Header("follower-1", 0, START_S), 1, (0.0, 0.0, 0.0), zero, zero,
                          zero, zero, START_S))
    ragged = ((0.0, 0.0, 0.0), (0.0,), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    asm.add(TruthSnapshot(Header("sim-0", 1, START_S), 0.0, ragged, ragged,
                          ((0.0, 0.0), (0.0, 0.0)), ((0.0, 0.0), (0.0, 0.0))))
    assert asm.drops == {"truth_shape": 2, "state_index": 1, "state_shape": 1}
    assert asm.truth_count == 0 and asm.state_counts() == [0] * 4


def test_no_truth_no_state_at_all_or_no_sample_in_window_is_a_named_error(
    paper: Scenario,
) -> None:
    with pytest.raises(DeployError, match="no truth"):
        RunAssembler(paper.n, paper.m).build()
    run = SynthRun(paper, SwarmKeys("u"), START_S)
    asm = RunAssembler(paper.n, paper.m)
    for _, msg in run.samples():
        if not isinstance(msg, FollowerState):
            asm.add(msg)
    with pytest.raises(DeployError, match="no follower sent a state"):
        asm.build()
    late = RunAssembler(paper.n, paper.m)
    late.add(dataclasses.replace(run.control(Stamper("l"), "start"), start_stamp_s=START_S + 99))
    for _, msg in run.samples():
        late.add(msg)
    with pytest.raises(DeployError, match="window"):
        late.build()


def without_follower(scenario: Scenario, run: SynthRun, silent: int) -> RunAssembler:
    asm = RunAssembler(scenario.n, scenario.m)
    asm.add(run.control(Stamper("launcher-0"), "start"))
    for _, msg in run.samples():
        if not (isinstance(msg, FollowerState) and msg.index == silent):
            asm.add(msg)
    return asm


def test_a_follower_that_sent_no_state_keeps_the_run_and_is_named(
    paper: Scenario, tmp_path: Path
) -> None:
    run = SynthRun(paper, SwarmKeys("u"), START_S, duration_s=2.0)
    out = without_follower(paper, run, 3).build()
    assert out.silent == (3,)
    assert np.isnan(out.series.estimate_m[:, 3]).all()
    assert np.isnan(out.series.command_m_s[:, 3]).all()
    assert np.isfinite(out.series.estimate_m[:, :3]).all()
    assert np.isfinite(out.series.follower_pos_m).all()  # its truth is still there
    assert out.followers[3].states == 0 and out.followers[3].age_p99_ms is None
    recent = without_follower(paper, run, 3).recent_series(1.0)
    assert recent is not None and np.isnan(recent.estimate_m[:, 3]).all()
    live = live_errors(without_follower(paper, run, 3), RunInfo.from_scenario(paper, "x", 2.0))
    assert live["max_estimator_error_m"] is not None and live["max_estimator_error_m"] < 1e-6

    metrics = write_final_outputs(tmp_path, paper, without_follower(paper, run, 3), {})
    assert metrics is not None and metrics.estimator_error_m < 1e-6  # over followers 0..2
    doc = json.loads((tmp_path / "metrics.json").read_text())
    assert doc["silent_followers"] == [3] and "error" not in doc
    assert doc["radius_error_m"] < 1e-9 and doc["angle_error"] < 1e-9
    csv = (tmp_path / "series.csv").read_text().splitlines()
    assert len(csv) == 102 and "nan" in csv[1]
    for name in ("performance.png", "trajectory.png"):
        assert (tmp_path / name).is_file(), name


def test_metrics_equal_those_of_write_run_outputs_on_the_same_data(
    paper: Scenario, tmp_path: Path
) -> None:
    run = SynthRun(paper, SwarmKeys("u"), START_S, duration_s=2.0)
    asm = fed(paper, run)
    metrics = write_final_outputs(tmp_path / "rec", paper, asm, {"recorder": {"x": 1}})
    assert metrics is not None
    # The same data assembled by hand, straight through the code `enclose simulate` uses.
    t = np.round(np.arange(0, 101) * 0.02, 12)
    direct = RunSeries(
        t, np.stack([formation_m(paper, x) for x in t]),
        np.stack([np.tile(lap_m(x), (paper.n, 1)) for x in t]),
        np.stack([np.tile((0.1 * np.cos(x - 0.004), 0.1 * np.sin(x - 0.004)), (paper.n, 1))
                  for x in t]),
        np.stack([targets_m(paper, x) for x in t]))
    expected = write_run_outputs(tmp_path / "direct", direct,
                                 RunInfo.from_scenario(paper, "networked", 2.0))
    got = json.loads((tmp_path / "rec" / "metrics.json").read_text())
    for name, value in expected.as_dict().items():
        # Carrying r_i over a lag of two 1.7e9 s stamps (ulp 0.24 us) costs ~1e-7 m.
        tol = 1e-6 if name == "estimator_error_m" else 1e-9
        assert got[name] == pytest.approx(value, abs=tol), name
    assert got["radius_error_m"] < 1e-9 and got["angle_error"] < 1e-9
    assert got["estimator_error_m"] < 1e-6
    assert got["filled_samples"] == 0 and got["recorder"] == {"x": 1}
    assert got["state_age_p99_ms"] == pytest.approx([4.0] * 4, abs=1e-3)
    for name in ("series.csv", "run.json", "performance.png", "trajectory.png"):
        assert (tmp_path / "rec" / name).is_file(), name


def test_recent_series_is_the_last_second(paper: Scenario) -> None:
    run = SynthRun(paper, SwarmKeys("u"), START_S, duration_s=3.0, pre_s=0.0, post_s=0.0)
    asm = fed(paper, run)
    recent = asm.recent_series(1.0)
    assert recent is not None
    assert recent.t_s[-1] == pytest.approx(3.0) and recent.t_s[0] == pytest.approx(2.0)
    assert asm.latest_experiment_time_s() == pytest.approx(3.0)
