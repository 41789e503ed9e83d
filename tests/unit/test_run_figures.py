"""Figures that show what happened: marks for faults, pauses, deaths, restarts and
membership changes; link health over time (links.csv -> links.png)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from agents.analysis.metrics import error_series
from agents.loading.scenario_file import load_scenario
from agents.lockstep.engine import simulate_lockstep
from deploy.report.link_figures import link_health_figure
from deploy.report.link_history import LinkHistory, read_links_csv
from deploy.report.marks import Mark, event_marks, run_marks
from deploy.report.run_figures import performance_figure, trajectory_figure
from deploy.report.run_report import regenerate_figures, write_run_outputs
from deploy.report.rundir import RunInfo
from transport.messages import Header, ProcessStatus

EVENTS = [
    {"t_s": 1.0, "process": "follower-1", "event": "fault", "action": "pause", "duration_s": 0.5},
    {"t_s": 1.5, "process": "follower-1", "event": "resumed"},
    {"t_s": 2.0, "process": "follower-2", "event": "fault", "action": "kill"},
    {"t_s": 2.0, "process": "follower-2", "event": "died", "signal": "SIGKILL"},
    {"t_s": 3.0, "process": "follower-2", "event": "restarted", "pid": 9},
    {"t_s": "bad"},
]


def status(i: int, stamp_s: float, **counters: int) -> ProcessStatus:
    return ProcessStatus(Header(f"follower-{i}", 0, stamp_s), "follower", i, "running", counters)


def test_launch_events_become_marks_and_pauses_become_bands() -> None:
    marks = event_marks({"events": EVENTS})
    assert [(m.t_s, m.kind, m.process) for m in marks] == [
        (1.0, "pause", "follower-1"), (2.0, "fault", "follower-2"),
        (2.0, "died", "follower-2"), (3.0, "restart", "follower-2")]
    assert marks[0].end_s == 1.5 and marks[0].follower == 1
    assert event_marks(None) == [] and event_marks({"events": None}) == []


def test_link_history_gives_loss_and_age_per_interval_and_survives_a_restart() -> None:
    h = LinkHistory()
    h.add(status(1, 100.0, rx_f0=50, seq_first_f0=0, seq_last_f0=49, age_n_f0=50,
                 age_sum_us_f0=500_000))
    h.add(status(1, 101.0, rx_f0=90, seq_first_f0=0, seq_last_f0=99, age_n_f0=90,
                 age_sum_us_f0=1_300_000, age_p99_us_f0=25_000))
    h.add(status(1, 102.0, rx_f0=10, seq_first_f0=120, seq_last_f0=129, age_n_f0=10,
                 age_sum_us_f0=100_000))  # follower 1 restarted: its counters begin again
    first, second, third = h.samples()
    assert first.link == "f0->f1" and first.delivered is None  # no interval yet
    assert second.delivered == pytest.approx(40 / 50)  # 40 of 50 sequence numbers arrived
    assert second.age_mean_ms == pytest.approx(800_000 / 40 / 1000)  # 20 ms
    assert second.age_p99_ms == 25.0 and second.offered == 100
    assert third.delivered is None and third.age_mean_ms is None
    summary = h.summary()
    assert summary["count"] == 1 and summary["silent"] == []


def ring_status(i: int, k: int, stamp_s: float, n: int = 4) -> ProcessStatus:
    """Follower i's k-th status in a ring of n: one link in, from its predecessor, which
    delivers all of its 10 messages a second."""
    j = (i - 1) % n
    return status(i, stamp_s, **{f"rx_f{j}": 10 * (k + 1), f"seq_last_f{j}": 10 * k + 9})


def test_links_are_not_silent_when_all_statuses_are_old_but_fresh_to_each_other() -> None:
    """A recorder 5 s behind the bus: every status it has is 5 s old, yet all kept coming.
    Silence is judged against the newest status, not the wall clock (no `now` at all)."""
    h = LinkHistory()
    for k in range(3):
        for i in range(4):
            h.add(ring_status(i, k, 100.0 + k + 0.1 * i))
    summary = h.summary()  # the wall clock would be ~107.3 here
    assert summary["count"] == 4 and summary["silent"] == []
    assert summary["min_delivered"] == 1.0


def test_a_receiver_whose_statuses_stopped_while_others_went_on_is_silent() -> None:
    h = LinkHistory()
    for k in range(9):
        for i in range(4):
            if i != 2 or k <= 4:  # follower 2 says nothing after 104 s, the others go to 108 s
                h.add(ring_status(i, k, 100.0 + k))
    summary = h.summary()
    assert summary["silent"] == ["f1->f2"] and summary["count"] == 4


def test_links_csv_round_trip(tmp_path: Path) -> None:
    h = LinkHistory()
    for k in range(3):
        h.add(status(0, 100.0 + k, rx_sensor=10 * k, seq_first_sensor=0,
                     seq_last_sensor=10 * k, age_n_sensor=10 * k, age_sum_us_sensor=30_000 * k))
    h.write_csv(tmp_path / "links.csv", start_stamp_s=99.0)
    links = read_links_csv(tmp_path / "links.csv")
    cols = links["sensor->f0"]
    assert list(cols["t_s"]) == [1.0, 2.0, 3.0]
    assert math.isnan(cols["delivered"][0]) and cols["delivered"][1] == 1.0
    assert cols["age_mean_ms"][2] == pytest.approx(3.0)
    assert read_links_csv(tmp_path / "missing.csv") == {}


@pytest.fixture(scope="module")
def short_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 4-s lock-step run with a networked run's extra files: links.csv and launch.json."""
    paper = load_scenario("paper")
    run_dir = tmp_path_factory.mktemp("run")
    series = simulate_lockstep(paper, 0.02, 4.0)
    (run_dir / "launch.json").write_text(json.dumps({"events": EVENTS}))
    h = LinkHistory()
    for k in range(5):
        h.add(status(2, 1000.0 + k, rx_f1=48 * k, seq_first_f1=0, seq_last_f1=50 * k,
                     age_n_f1=48 * k, age_sum_us_f1=480_000 * k))
    h.write_csv(run_dir / "links.csv", start_stamp_s=1000.0)
    write_run_outputs(run_dir, series, RunInfo.from_scenario(paper, "networked", 4.0),
                      {"membership": {"changes_s": [2.5]}}, [2.5])
    return run_dir


def test_every_figure_draws_the_marks_of_the_run(short_run: Path, tmp_path: Path) -> None:
    paper = load_scenario("paper")
    series = simulate_lockstep(paper, 0.02, 4.0)
    marks = run_marks(short_run, [2.5])
    assert [m.kind for m in marks] == ["pause", "fault", "died", "membership", "restart"]
    errors = error_series(series, paper.successor, np.asarray(paper.pattern.angles_rad),
                          paper.pattern.rho_d_m)
    drawn = performance_figure(series, errors, (0.0999, 0.0199), tmp_path / "p.png", marks)
    assert drawn == marks
    late = [*marks, Mark(99.0, "fault", "sim")]  # after the series: not on the trajectory
    assert trajectory_figure(series, 8.0, tmp_path / "t.png", late) == marks
    links = read_links_csv(short_run / "links.csv")
    assert link_health_figure(links, tmp_path / "l.png", marks) == marks
    for name in ("p.png", "t.png", "l.png"):
        assert (tmp_path / name).stat().st_size > 10_000


def test_report_redraws_the_link_health_figure(short_run: Path) -> None:
    (short_run / "links.png").unlink()
    drawn = {name: (short_run / name).read_bytes() for name in ("performance.png",
                                                                "trajectory.png")}
    paths = regenerate_figures(short_run)
    assert short_run / "links.png" in paths
    assert (short_run / "links.png").stat().st_size > 10_000
    # The run drew from the rows the report reads back from series.parquet: the same.
    assert all((short_run / name).read_bytes() == data for name, data in drawn.items())


def test_report_reads_series_csv_where_a_run_has_no_parquet(short_run: Path,
                                                            tmp_path: Path) -> None:
    old = tmp_path / "old"
    old.mkdir()
    for name in ("run.json", "metrics.json", "series.csv"):
        (old / name).write_bytes((short_run / name).read_bytes())
    paths = regenerate_figures(old)
    assert [p.name for p in paths] == ["performance.png", "trajectory.png"]
    assert all(p.stat().st_size > 10_000 for p in paths)


@pytest.mark.timeout(120)
def test_a_large_swarm_gets_a_colour_bar_not_a_legend_that_squeezes_the_panels(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import deploy.report.run_figures as figures

    ring32 = load_scenario("ring32")
    series = simulate_lockstep(ring32, 0.02, 2.0)
    errors = error_series(series, ring32.successor, np.asarray(ring32.pattern.angles_rad),
                          ring32.pattern.rho_d_m)
    kept: list[object] = []
    monkeypatch.setattr(figures.plt, "close", kept.append)
    performance_figure(series, errors, (0.0999, 0.0199), tmp_path / "p.png")
    trajectory_figure(series, 8.0, tmp_path / "t.png")
    perf, traj = kept
    panels = [ax for ax in perf.axes if ax.get_title()]  # type: ignore[attr-defined]
    assert len(panels) == 6
    # A 32-name legend made tight_layout shrink the panels to slivers (issue 15's ring32).
    assert min(ax.get_position().height for ax in panels) > 0.2
    legends = [ax.get_legend() for ax in [*perf.axes, *traj.axes]]  # type: ignore[attr-defined]
    assert all(len(leg.get_texts()) <= 12 for leg in legends if leg is not None)
    assert any(ax.get_ylabel() == "follower" for ax in perf.axes)  # type: ignore[attr-defined]


def test_a_network_fault_is_banded_on_every_figure_and_measured(tmp_path: Path) -> None:
    paper = load_scenario("paper")
    series = simulate_lockstep(paper, 0.02, 4.0)
    info = dataclasses.replace(RunInfo.from_scenario(paper, "networked", 4.0),
                               net_faults=(("partition 1,2|3,4 1-2 s", 1.0, 2.0),))
    h = LinkHistory()
    for k in range(5):
        h.add(status(2, 1000.0 + k, rx_f1=48 * k, seq_first_f1=0, seq_last_f1=50 * k))
    h.write_csv(tmp_path / "links.csv", start_stamp_s=1000.0)
    metrics = write_run_outputs(tmp_path, series, info)
    doc = json.loads((tmp_path / "metrics.json").read_text())
    (fault,) = doc["net_faults"]
    assert fault["label"] == "partition 1,2|3,4 1-2 s" and fault["at_s"] == 1.0
    assert fault["min_separation_m"] >= metrics.min_separation_m > 0.0
    assert doc["min_separation_m"] == metrics.min_separation_m
    assert [m.kind for m in run_marks(tmp_path, [], info.net_faults)] == ["network"]
    assert json.loads((tmp_path / "run.json").read_text())["net_faults"] == [
        ["partition 1,2|3,4 1-2 s", 1.0, 2.0]]
    paths = regenerate_figures(tmp_path)  # run.json read back: the fault again
    assert {p.name for p in paths} == {"performance.png", "trajectory.png", "links.png"}
