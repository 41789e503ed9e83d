"""The recorder's outputs read chunk by chunk from disk equal those of the whole run at once.

The reference here aligns the whole run in memory, as the recorder did before it spilled to
disk (`reference_series`); the chunked assembly, its metrics and membership phases must give
the same numbers bit for bit, whatever the chunk and block sizes and the arrival order.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import random
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.analysis.metrics import (
    ErrorSeries,
    Metrics,
    MetricsAccumulator,
    WindowAccumulator,
    compute_metrics,
    error_series,
    least,
    separation_series,
    settle_time,
    worst,
)
from agents.analysis.timeseries import RunSeries
from agents.loading.scenario_file import load_scenario
from agents.membership.ring_accuracy import PhaseReport, membership_phases, phase_report
from agents.scenario.model import Scenario
from deploy.recording.assembler import RunAssembler
from deploy.recording.chunks import EPS_S
from deploy.recording.spill import RowSpill
from deploy.report.link_history import read_links_csv
from deploy.report.rundir import SeriesWriter, read_series, series_rows
from tests.recorder_synth import SynthRun
from transport.key_exprs import SwarmKeys
from transport.messages import FollowerState, Message, Stamper, TruthSnapshot

START_S = 1_700_000_000.0
SERIES_FIELDS = [f.name for f in dataclasses.fields(RunSeries)]


@pytest.fixture(scope="module")
def paper() -> Scenario:
    return load_scenario("paper")


def messy_run(scenario: Scenario, seed: int, silent: int | None = None) -> list[Message]:
    """A 12-s run as a network delivers it: local disorder, re-deliveries, a follower whose
    first state comes 1.3 s late, jittered state stamps (ties and reversals), before and
    after the window."""
    run = SynthRun(scenario, SwarmKeys("u"), START_S, duration_s=12.0, pre_s=0.5, post_s=0.5)
    rng = random.Random(seed)
    msgs: list[Message] = [run.control(Stamper("l"), "start")]
    for _, m in run.samples():
        if isinstance(m, FollowerState):
            if m.index == silent or (m.index == 2 and m.header.stamp_s < START_S + 1.3):
                continue
            if rng.random() < 0.1:
                jitter = rng.choice([0.0, 0.02, -0.02, rng.uniform(-0.05, 0.05)])
                m = dataclasses.replace(m, header=dataclasses.replace(
                    m.header, stamp_s=m.header.stamp_s + jitter))
        msgs.append(m)
    for k in range(1, len(msgs) - 30, 5):
        j = k + rng.randrange(30)
        msgs[k], msgs[j] = msgs[j], msgs[k]
    msgs += [msgs[rng.randrange(1, len(msgs))] for _ in range(150)]
    return msgs


def reference_series(msgs: list[Message], n: int) -> tuple[RunSeries, list[tuple[int, float]]]:
    """The whole run aligned at once; per follower (filled samples, p99 age in ms)."""
    truth = [m for m in msgs if isinstance(m, TruthSnapshot)]
    stamps = np.array([m.header.stamp_s for m in truth])
    start, duration = START_S, 12.0
    t = stamps - start
    inside = np.nonzero((t >= -EPS_S) & (t <= duration + EPS_S))[0]
    _, first = np.unique(stamps[inside], return_index=True)
    rows = inside[first]
    q = stamps[rows]
    est, cmd = np.full((len(q), n, 2), np.nan), np.full((len(q), n, 2), np.nan)
    stats = []
    for i in range(n):
        mine = [m for m in msgs if isinstance(m, FollowerState) and m.index == i]
        if not mine:
            stats.append((0, math.nan))
            continue
        s = np.array([m.header.stamp_s for m in mine])
        order = np.argsort(s, kind="stable")
        idx = np.searchsorted(s[order], q + EPS_S, side="right") - 1
        filled = idx < 0
        idx[filled] = 0
        used = order[idx]
        lag = np.where(filled, 0.0, q - s[used])[:, None]
        est[:, i] = np.array([m.r_m for m in mine])[used] + lag * np.array(
            [m.dr_m_s for m in mine])[used]
        cmd[:, i] = np.array([m.u_m_s for m in mine])[used]
        stats.append((int(filled.sum()), float(np.percentile(1000.0 * (q - s[used])[~filled], 99))))
    pos = np.stack([np.asarray(truth[r].follower_pos_m)[:, :2] for r in rows])
    tgt = np.stack([np.asarray(truth[r].target_pos_m) for r in rows])
    return RunSeries(q - start, pos, est, cmd, tgt), stats


def assembled(msgs: list[Message], scenario: Scenario, block_rows: int) -> RunAssembler:
    asm = RunAssembler(scenario.n, scenario.m, block_rows=block_rows)
    for m in msgs:
        asm.add(m)
    return asm


@pytest.mark.timeout(120)
@pytest.mark.parametrize(("seed", "chunk_rows", "block_rows", "silent"),
                         [(1, 64, 7, None), (2, 128, 50, 3), (3, 5000, 2048, None)])
def test_chunks_equal_the_whole_run_aligned_at_once(
    paper: Scenario, seed: int, chunk_rows: int, block_rows: int, silent: int | None
) -> None:
    msgs = messy_run(paper, seed, silent)
    expected, stats = reference_series(msgs, paper.n)
    asm = assembled(msgs, paper, block_rows).assemble(chunk_rows=chunk_rows)
    chunks = list(asm.chunks())
    assert len(chunks) == math.ceil(len(expected.t_s) / chunk_rows)
    assert np.array_equal(asm.t_s, expected.t_s)
    for name in SERIES_FIELDS:
        got = np.concatenate([getattr(c, name) for c in chunks])
        assert np.array_equal(got, getattr(expected, name), equal_nan=True), name
    for i, f in enumerate(asm.followers):
        assert f.filled_samples == stats[i][0]
        assert (f.age_p99_ms is None and math.isnan(stats[i][1])) or f.age_p99_ms == stats[i][1]
    assert asm.followers[2].filled_samples > 0
    assert asm.silent == (() if silent is None else (silent,))


def test_recent_series_keeps_a_bounded_window(paper: Scenario) -> None:
    run = SynthRun(paper, SwarmKeys("u"), START_S, duration_s=40.0, pre_s=0.0, post_s=0.0)
    asm = RunAssembler(paper.n, paper.m)
    asm.add(run.control(Stamper("l"), "start"))
    for _, m in run.samples():
        asm.add(m)
    recent = asm.recent_series(1.0)
    assert recent is not None and len(recent.t_s) == 51
    assert recent.t_s[0] == pytest.approx(39.0) and recent.t_s[-1] == pytest.approx(40.0)
    whole = asm.build().series
    assert whole is not None and np.allclose(recent.estimate_m, whole.estimate_m[-51:])
    assert asm.truth_count == 2001 and asm.state_counts() == [2001] * 4


def test_spill_blocks_hold_every_row_of_a_key_range() -> None:
    rng = np.random.default_rng(4)
    spill = RowSpill(3, block_rows=16)
    rows = np.column_stack([np.cumsum(rng.normal(1.0, 3.0, 500)), rng.normal(size=(500, 2))])
    for row in rows:
        spill.append(row)
    assert spill.rows == 500
    for lo, hi in ((-np.inf, np.inf), (100.0, 200.0), (rows[17, 0], rows[17, 0])):
        got = np.concatenate([b[(b[:, 0] >= lo) & (b[:, 0] <= hi)] for b in spill.blocks(lo, hi)])
        assert np.array_equal(got, rows[(rows[:, 0] >= lo) & (rows[:, 0] <= hi)])
    spill.close()


def random_errors(rng: np.random.Generator, k: int, n: int) -> tuple[RunSeries, ErrorSeries]:
    series = RunSeries(np.arange(k) * 0.1, rng.normal(size=(k, n, 2)), rng.normal(size=(k, n, 2)),
                       rng.normal(size=(k, n, 2)), rng.normal(size=(k, 2, 2)))
    errs = [rng.normal(scale=0.05, size=(k, n)) for _ in range(5)]
    errs[2][rng.random((k, n)) < 0.3] = np.nan  # silent followers' estimates
    series.command_m_s[rng.random(k) < 0.1] = np.nan
    return series, ErrorSeries(*errs)


def reference_metrics(series: RunSeries, errors: ErrorSeries, steady_from_s: float,
                      eps_rho_m: float, eps_delta: float) -> Metrics:
    """The metrics of the whole series at once (as they were computed before chunks)."""
    steady = series.t_s >= steady_from_s
    if not np.any(steady):
        steady = np.ones_like(series.t_s, dtype=bool)
    inside = np.all(
        (np.abs(errors.e_rho_m) < eps_rho_m) & (np.abs(errors.e_delta) < eps_delta), axis=1)
    jumps = np.linalg.norm(np.diff(series.command_m_s, axis=0), axis=2)
    steady_jumps = jumps[steady[1:] & steady[:-1]]
    separation = separation_series(series.follower_pos_m)
    return Metrics(
        steady_from_s=float(steady_from_s),
        estimator_error_m=worst(errors.estimator_error_m[steady]),
        radius_error_m=float(np.abs(errors.e_rho_m[steady]).max()),
        angle_error=float(np.abs(errors.e_delta[steady]).max()),
        settle_time_s=settle_time(series.t_s, inside),
        command_jump_m_s=worst(steady_jumps) if steady_jumps.size else 0.0,
        duration_s=float(series.t_s[-1] - series.t_s[0]),
        samples=len(series.t_s),
        min_separation_m=least(separation),
        min_separation_transient_m=least(separation[series.t_s < steady_from_s]),
        min_separation_steady_m=least(separation[series.t_s >= steady_from_s]),
    )


@settings(max_examples=80, deadline=None)

def feed_in_chunks(acc: MetricsAccumulator | WindowAccumulator, series: RunSeries,
                   errors: ErrorSeries, cuts: list[int],
                   k: int) -> None:
    """`acc.add` the k rows of `series` and `errors` cut at `cuts` (those below k)."""
    bounds = [0, *sorted({c for c in cuts if c < k}), k]
    for a, b in itertools.pairwise(bounds):
        rows = np.arange(a, b)
        acc.add(series.take(rows), ErrorSeries(*(getattr(errors, f.name)[rows]
                                                 for f in dataclasses.fields(ErrorSeries))))

@given(seed=st.integers(0, 10**6), k=st.integers(1, 60), cuts=st.lists(st.integers(1, 59)),
       steady_from=st.sampled_from([0.0, 2.5, 5.9, 99.0]))
def test_metrics_fed_in_chunks_are_those_of_the_whole(
    seed: int, k: int, cuts: list[int], steady_from: float
) -> None:
    series, errors = random_errors(np.random.default_rng(seed), k, 3)
    whole = reference_metrics(series, errors, steady_from, 0.05, 0.05)
    assert same(compute_metrics(series, errors, steady_from, 0.05, 0.05), whole)
    acc = MetricsAccumulator(steady_from, 0.05, 0.05)
    feed_in_chunks(acc, series, errors, cuts, k)
    assert same(acc.result(), whole)


def same(got: Metrics, expected: Metrics) -> bool:
    """Equal, field by field, NaN where NaN."""
    return all(a == b or (isinstance(a, float) and isinstance(b, float)
                          and math.isnan(a) and math.isnan(b))
               for a, b in zip(dataclasses.astuple(got), dataclasses.astuple(expected),
                               strict=True))


def test_membership_phases_fed_in_chunks_are_those_of_the_whole(paper: Scenario) -> None:
    msgs = messy_run(paper, 5)
    series, _ = reference_series(msgs, paper.n)
    phases = membership_phases([(-1.0, frozenset(range(4))), (4.0, frozenset({0, 1, 3})),
                                (8.0, frozenset(range(4)))], float(series.t_s[-1]))
    report = PhaseReport(paper, phases)
    for a in range(0, len(series.t_s), 97):
        report.add(series.take(np.arange(a, min(a + 97, len(series.t_s)))))
    assert report.result() == phase_report(series, paper, phases)
    assert len(report.result()) == 3 and "reform_s" in report.result()[1]


def test_parquet_holds_the_csv_rows_at_full_precision_and_reads_back_thinned(
    paper: Scenario, tmp_path: Path
) -> None:
    series, _ = reference_series(messy_run(paper, 6), paper.n)
    errors = error_series(series, paper.successor, np.asarray(paper.pattern.angles_rad), 8.0)
    with SeriesWriter(tmp_path, paper.n, paper.m) as writer:
        for a in range(0, len(series.t_s), 250):
            rows = np.arange(a, min(a + 250, len(series.t_s)))
            writer.add(series.take(rows), error_series(series.take(rows), paper.successor,
                                                       np.asarray(paper.pattern.angles_rad), 8.0))
    back = read_series(tmp_path / "series.parquet", paper.n, paper.m)
    for name in SERIES_FIELDS:
        assert np.array_equal(getattr(back, name), getattr(series, name), equal_nan=True)
    csv = read_series(tmp_path / "series.csv", paper.n, paper.m)
    assert np.allclose(csv.estimate_m, series.estimate_m, rtol=1e-8, equal_nan=True)
    assert len((tmp_path / "series.csv").read_text().splitlines()) == len(series.t_s) + 1
    assert np.array_equal(series_rows(series, errors)[:, 0], series.t_s)
    thin = read_series(tmp_path / "series.parquet", paper.n, paper.m, max_rows=100)
    assert 50 < len(thin.t_s) <= 101 and thin.t_s[-1] == series.t_s[-1]
    assert np.array_equal(thin.t_s, series.decimate(math.ceil(len(series.t_s) / 100)).t_s)


def test_a_long_links_csv_reads_back_in_bins_that_keep_the_worst(tmp_path: Path) -> None:
    lines = ["t_s,link,rx,offered,delivered,age_mean_ms,age_p50_ms,age_p99_ms"]
    for k in range(1000):
        for link in ("f0->f1", "f1->f0"):
            delivered = 0.2 if (k == 503 and link == "f0->f1") else 1.0
            lines.append(f"{k}.000,{link},{k},{k + 1},{delivered},{10 + (k == 707)},,")
    (tmp_path / "links.csv").write_text("\n".join(lines) + "\n")
    full = read_links_csv(tmp_path / "links.csv")
    assert len(full["f0->f1"]["t_s"]) == 1000
    thin = read_links_csv(tmp_path / "links.csv", max_points=200)
    cols = thin["f0->f1"]
    assert len(cols["t_s"]) == 100 and cols["t_s"][-1] == 999.0
    assert np.nanmin(cols["delivered"]) == 0.2 and np.nanmax(cols["age_mean_ms"]) == 11.0
    assert np.isnan(cols["age_p50_ms"]).all()


def reference_window(series: RunSeries, errors: ErrorSeries, start: float, end: float,
                     eps_rho_m: float, eps_delta: float) -> dict[str, float | None]:
    """A network fault's window over the whole series at once."""
    during = (series.t_s >= start) & (series.t_s < end)
    after = series.t_s >= end
    inside = np.all((np.abs(errors.e_rho_m) < eps_rho_m) & (np.abs(errors.e_delta) < eps_delta),
                    axis=1)
    back = settle_time(series.t_s[after], inside[after])
    return {
        "radius_error_m": worst(np.abs(errors.e_rho_m[during]).ravel()),
        "angle_error": worst(np.abs(errors.e_delta[during]).ravel()),
        "estimator_error_m": worst(errors.estimator_error_m[during].ravel()),
        "min_separation_m": least(separation_series(series.follower_pos_m[during])),
        "recovery_s": None if back is None else max(0.0, back - end),
    }


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10**6), k=st.integers(1, 60), cuts=st.lists(st.integers(1, 59)),
       window=st.sampled_from([(1.0, 2.5), (0.0, 6.0), (5.5, 9.0), (-1.0, 0.05)]))
def test_fault_windows_fed_in_chunks_are_those_of_the_whole(
    seed: int, k: int, cuts: list[int], window: tuple[float, float]
) -> None:
    series, errors = random_errors(np.random.default_rng(seed), k, 3)
    acc = WindowAccumulator(window, 0.05, 0.05)
    feed_in_chunks(acc, series, errors, cuts, k)
    got, expected = acc.result(), reference_window(series, errors, *window, 0.05, 0.05)
    assert got.keys() == expected.keys()
    for name, value in expected.items():
        assert got[name] == value or (value is not None and math.isnan(value)
                                      and math.isnan(got[name] or 0.0)), name
