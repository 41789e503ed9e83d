"""`enclose sweep`: the sweep file, its cells, resume, the table and figures, with a fake runner."""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest

from deploy.cli import main
from deploy.sweep.command import run_sweep
from deploy.sweep.figures import error_against
from deploy.sweep.spec import SweepSpec, load_sweep, parse_sweep
from deploy.sweep.sweep_progress import SweepProgress, clock_text
from deploy.sweep.table import (
    RECOVERY,
    CellState,
    Row,
    collect,
    columns,
    markdown,
    pick_metrics,
    row_values,
)
from errors import ConfigError

pytestmark = pytest.mark.timeout(60)

SWEEP = """
scenario = "paper"
duration_s = 8
out = "out"
[grid]
estimator = ["paper", "robust"]
loss = [0.0, 0.2]
"delay_ms+jitter_ms" = [[0, 0], [50, 20]]
[fixed]
loss_model = "independent"
"""


def sweep_file(tmp_path: Path, text: str = SWEEP) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(text)
    return path


def doc(**changes: Any) -> dict[str, Any]:
    base: dict[str, Any] = {"duration_s": 8, "grid": {"loss": [0.0, 0.1]}}
    base.update(changes)
    return {k: v for k, v in base.items() if v is not None}


class FakeRunner:
    """Writes what a finished `enclose run` writes; `fail` cells exit 1 without metrics."""

    def __init__(self, fail: Sequence[str] = (), interrupt_at: int | None = None,
                 links: bool = False) -> None:
        self.calls: list[Path] = []
        self.fail, self.interrupt_at, self.links = set(fail), interrupt_at, links

    def run_cell(self, argv: Sequence[str], out_dir: Path, timeout_s: float) -> int:
        assert timeout_s > 8 and argv[0] == "run" and argv[argv.index("--out") + 1] == str(out_dir)
        self.calls.append(out_dir)
        if self.interrupt_at == len(self.calls):
            self.write(argv, out_dir)  # an orderly stop leaves clean outputs
            raise KeyboardInterrupt
        if out_dir.name in self.fail:
            return 1
        self.write(argv, out_dir)
        return 0

    def write(self, argv: Sequence[str], out_dir: Path) -> None:
        loss = float(argv[argv.index("--loss") + 1]) if "--loss" in argv else 0.0
        robust = "robust" in argv
        metrics: dict[str, Any] = {
            "estimator_error_m": 0.01 + loss * (0.1 if robust else 1.0),
            "radius_error_m": 0.02 + loss * 0.5,
            "angle_error": 0.005 + loss * 0.1,
            "settle_time_s": None if loss > 0.1 else 6.5,
            "command_jump_m_s": 0.2,
        }
        if self.links:
            ratios = {"f0->f1": 1 - loss, "f1->f2": 1.0, "sensor->f1": 0.5}
            metrics["links"] = {k: {"delivered_ratio": v} for k, v in ratios.items()}
        (out_dir / "metrics.json").write_text(json.dumps(metrics))
        launch = {"processes": {"sim": {"pid": 1, "exit_code": 0}, "f": {"pid": 2, "exit_code": 0}}}
        (out_dir / "launch.json").write_text(json.dumps(launch))


def rows(spec: SweepSpec) -> list[dict[str, str]]:
    with open(spec.out / "results.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_cells_are_the_product_in_file_order_with_stable_names(tmp_path: Path) -> None:
    spec = load_sweep(sweep_file(tmp_path))
    names = [c.name for c in spec.cells()]
    assert len(names) == 8 and len(set(names)) == 8
    assert names[0] == "estimator=paper__loss=0__delay_ms=0__jitter_ms=0__seed=1"
    assert names[1] == "estimator=paper__loss=0__delay_ms=50__jitter_ms=20__seed=1"
    assert names[-1] == "estimator=robust__loss=0.2__delay_ms=50__jitter_ms=20__seed=1"
    assert spec.out == tmp_path / "out"
    argv = spec.run_argv(spec.cells()[3], tmp_path / "c")
    assert argv == ["run", "paper", "--duration", "8", "--out", str(tmp_path / "c"),
                    "--loss-model", "independent", "--estimator", "paper", "--loss", "0.2",
                    "--delay-ms", "50", "--jitter-ms", "20", "--impair-seed", "1"]


def test_faults_and_restart_policies_sweep_like_network_flags(tmp_path: Path) -> None:
    grid = {"fault": ["none", "30:kill:follower-1"], "restart": ["on-failure", "never"]}
    spec = parse_sweep(doc(grid=grid), tmp_path / "s.toml")
    assert len(spec.cells()) == 4
    argv = spec.run_argv(spec.cells()[3], tmp_path / "c")
    assert argv[argv.index("--fault") + 1] == "30:kill:follower-1"
    assert argv[argv.index("--restart") + 1] == "never"


def test_repeats_give_one_cell_per_seed_and_paths_are_relative_to_the_file(
    tmp_path: Path,
) -> None:
    scen = Path(__file__).parents[2] / "agents" / "scenario" / "shipped" / "paper.toml"
    (tmp_path / "paper.toml").write_text(scen.read_text())
    spec = parse_sweep(doc(repeats=2, seed0=7, scenario="paper.toml"), tmp_path / "s.toml")
    assert spec.scenario == str(tmp_path / "paper.toml")
    assert [c.name for c in spec.cells()] == [
        "loss=0__seed=7", "loss=0__seed=8", "loss=0.1__seed=7", "loss=0.1__seed=8"]


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"grids": {}}, "grids"),
        ({"duration_s": None}, "duration_s"),
        ({"duration_s": -1}, "duration_s"),
        ({"duration_s": "90"}, "duration_s"),
        ({"repeats": 0}, "repeats"),
        ({"seed0": 1.5}, "seed0"),
        ({"scenario": "nope"}, "scenario"),
        ({"scenario": "missing.toml"}, "scenario"),
        ({"out": 3}, "out"),
        ({"grid": {"latency": [1]}}, "grid.latency"),
        ({"grid": {"delay-ms": [1]}}, "grid.delay-ms"),
        ({"grid": {"impair_seed": [1, 2]}}, "grid.impair_seed"),
        ({"grid": {"loss": []}}, "grid.loss"),
        ({"grid": {"loss": 0.1}}, "grid.loss"),
        ({"grid": {"loss": [0.0, "x"]}}, "grid.loss[1]"),
        ({"grid": {"loss": [0.0, 1.0]}}, "grid.loss[1]"),
        ({"grid": {"delay_ms": [-5]}}, "grid.delay_ms[0]"),
        ({"grid": {"loss": [0.1, 0.1]}}, "grid.loss[1]"),
        ({"grid": {"estimator": ["kalman"]}}, "grid.estimator[0]"),
        ({"grid": {"link": ["quic"]}}, "grid.link[0]"),
        ({"grid": {"delay_ms+jitter_ms": [[0, 0], [50]]}}, "grid.delay_ms+jitter_ms[1]"),
        ({"grid": {"loss": [0.1], "loss+delay_ms": [[0.1, 2]]}}, "grid.loss"),
        ({"fixed": {"loss_model": "bursty"}}, "fixed.loss_model"),
        ({"fixed": {"loss": 0.2}}, "grid.loss"),
        ({"fixed": {"colour": 1}}, "fixed.colour"),
        ({"fixed": []}, "fixed"),
        ({"grid": {"fault": ["30:explode:follower-1"]}}, "grid.fault[0]"),
        ({"grid": {"fault": ["none", "30:kill:follower-9"]}}, "grid.fault[1].target"),
        ({"grid": {"restart": ["sometimes"]}}, "grid.restart[0]"),
        ({"heatmap": ["loss"]}, "heatmap"),
        ({"heatmap": ["loss", "delay_ms"]}, "heatmap[1]"),
    ],
)
def test_bad_sweep_files_name_the_field(changes: dict[str, Any], field: str,
                                        tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as err:
        parse_sweep(doc(**changes), tmp_path / "s.toml")
    assert err.value.field == field, err.value


def test_bad_toml_and_cli_exit_code_2(tmp_path: Path) -> None:
    path = sweep_file(tmp_path, "duration_s = [")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_sweep(path)
    assert main(["sweep", str(sweep_file(tmp_path, "duration_s = 0\n[grid]\nloss=[0.1]"))]) == 2


def test_a_sweep_runs_every_cell_then_resume_skips_the_done_ones(tmp_path: Path) -> None:
    spec = load_sweep(sweep_file(tmp_path))
    runner = FakeRunner()
    assert run_sweep(spec, runner, tty=False, figures=False) == 0
    assert len(runner.calls) == 8
    first = (spec.out / "results.csv").read_text()
    again = FakeRunner()
    assert run_sweep(spec, again, tty=False, figures=False) == 0
    assert again.calls == []
    assert (spec.out / "results.csv").read_text() == first
    # a cell with a dead process and one cut short (no metrics) are run again, alone
    cells = [c.name for c in spec.cells()]
    launch = spec.out / cells[2] / "launch.json"
    launch.write_text(launch.read_text().replace('"exit_code": 0}}', '"exit_code": -9}}'))
    (spec.out / cells[5] / "metrics.json").unlink()
    silent = spec.out / cells[6] / "metrics.json"  # a follower never published: partial
    silent.write_text(json.dumps({**json.loads(silent.read_text()), "silent_followers": [1]}))
    assert collect(spec)[6].state.status == "silent"
    third = FakeRunner()
    assert run_sweep(spec, third, tty=False, figures=False) == 0
    assert [p.name for p in third.calls] == [cells[2], cells[5], cells[6]]


def test_a_failed_cell_is_recorded_and_the_sweep_goes_on(tmp_path: Path) -> None:
    spec = load_sweep(sweep_file(tmp_path))
    bad = spec.cells()[1].name
    assert run_sweep(spec, FakeRunner(fail=[bad]), tty=False, figures=False) == 1
    table = rows(spec)
    assert [r["status"] for r in table].count("done") == 7
    failed = next(r for r in table if r["cell"] == bad)
    assert failed["status"] == "failed" and failed["exit_code"] == "1"
    assert failed["estimator_error_m"] == ""
    rerun = FakeRunner()
    assert run_sweep(spec, rerun, tty=False, figures=False) == 0
    assert [p.name for p in rerun.calls] == [bad]


def test_changed_settings_make_cells_stale_and_rerun(tmp_path: Path) -> None:
    spec = load_sweep(sweep_file(tmp_path))
    run_sweep(spec, FakeRunner(), tty=False, figures=False)
    changed = load_sweep(sweep_file(tmp_path, SWEEP.replace("independent", "gilbert_elliott")))
    assert {r.state.status for r in collect(changed)} == {"stale"}
    runner = FakeRunner()
    assert run_sweep(changed, runner, tty=False, figures=False) == 0 and len(runner.calls) == 8


def test_table_rows_hold_values_status_and_metrics(tmp_path: Path) -> None:
    spec = load_sweep(sweep_file(tmp_path))
    run_sweep(spec, FakeRunner(links=True), tty=False, figures=False)
    table = rows(spec)
    assert list(table[0])[:7] == ["estimator", "loss", "delay_ms", "jitter_ms", "seed", "status",
                                  "exit_code"]
    assert len(table) == 8
    row = next(r for r in table if r["estimator"] == "robust" and r["loss"] == "0.2")
    assert row["status"] == "done" and row["exit_code"] == "0"
    assert float(row["estimator_error_m"]) == pytest.approx(0.03)
    assert row["settle_time_s"] == ""  # never settled
    assert float(row["delivered_ratio"]) == pytest.approx(0.9)
    md = (spec.out / "results.md").read_text()
    assert md.count("\n| robust |") == 4 and "8/8 cells done" in md


def test_report_only_gives_the_same_table(tmp_path: Path) -> None:
    path = sweep_file(tmp_path)
    spec = load_sweep(path)
    run_sweep(spec, FakeRunner(), tty=False, figures=False)
    first = (spec.out / "results.csv").read_text()
    (spec.out / "results.csv").unlink()
    assert main(["sweep", "--report-only", str(path)]) == 0
    assert (spec.out / "results.csv").read_text() == first


def test_figures_from_fake_results(tmp_path: Path) -> None:
    text = SWEEP.replace('out = "out"', 'out = "out"\nrepeats = 2')
    spec = load_sweep(sweep_file(tmp_path, text))
    run_sweep(spec, FakeRunner(links=True), tty=False)
    names = {p.name for p in spec.out.glob("*.png")}
    assert names == {
        "heatmap_estimator_error_m.png", "heatmap_radius_error_m.png", "heatmap_angle_error.png",
        "heatmap_settle_time_s.png", "heatmap_command_jump_m_s.png",
        "heatmap_delivered_ratio.png", "error_vs_loss.png", "error_vs_delay.png"}
    assert all((spec.out / n).stat().st_size > 10_000 for n in names)


class SeededRunner(FakeRunner):
    """As FakeRunner, with an estimator error that depends on the cell's seed."""

    def write(self, argv: Sequence[str], out_dir: Path) -> None:
        super().write(argv, out_dir)
        seed = int(argv[argv.index("--impair-seed") + 1])
        metrics = json.loads((out_dir / "metrics.json").read_text())
        metrics["estimator_error_m"] += 0.001 * seed
        (out_dir / "metrics.json").write_text(json.dumps(metrics))


def test_line_figures_have_error_bars_over_the_seeds(tmp_path: Path) -> None:
    text = SWEEP.replace('out = "out"', 'out = "out"\nrepeats = 3')
    spec = load_sweep(sweep_file(tmp_path, text))
    run_sweep(spec, SeededRunner(), tty=False, figures=False)
    done = [r for r in collect(spec) if r.state.done]
    bars = error_against(spec, done, "loss", tmp_path / "e.png")
    estimator_bars, radius_bars = bars[:2], bars[2:]  # one per estimator and panel
    seeds = sorted({r.cell.seed for r in done})
    spread = 0.001 * (seeds[-1] - seeds[0])
    for yerr in estimator_bars:  # from the mean down to the lowest seed, up to the highest
        assert yerr.shape == (2, 2)
        assert (yerr.sum(axis=0) == pytest.approx([spread, spread]))
    assert all(float(abs(y).max()) < 1e-12 for y in radius_bars)  # no spread: no bar


def test_the_sweep_ends_with_a_verdict(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    spec = load_sweep(sweep_file(tmp_path))
    bad = spec.cells()[0].name
    run_sweep(spec, FakeRunner(fail=[bad]), tty=False, figures=False)
    out = capsys.readouterr().out
    assert "\x1b" not in out
    lines = out.splitlines()
    assert lines[0] == "enclose sweep s: 7/8 cells done; 3 inside the paper's bounds, 4 outside"
    assert "estimator_error_m 0.21 m >= 0.0999" in lines[1]
    assert f"not done     {bad} (failed)" in lines[2]
    assert lines[3].startswith(f"  files        {spec.out}/ (results.csv, results.md")


def test_figures_skip_what_the_grid_cannot_show(tmp_path: Path,
                                                 caplog: pytest.LogCaptureFixture) -> None:
    spec = load_sweep(sweep_file(tmp_path, 'duration_s = 8\nout = "o"\n[grid]\nloss = [0.0, 0.1]'))
    caplog.set_level("INFO")
    run_sweep(spec, FakeRunner(), tty=False)
    assert {p.name for p in spec.out.glob("*.png")} == {"error_vs_loss.png"}
    assert "heatmaps skipped" in caplog.text and "error_vs_delay.png skipped" in caplog.text


def test_ctrl_c_stops_the_sweep_keeps_finished_cells_and_resumes(tmp_path: Path) -> None:
    spec = load_sweep(sweep_file(tmp_path))
    assert run_sweep(spec, FakeRunner(interrupt_at=3), tty=False, figures=False) == 130
    status = [r["status"] for r in rows(spec)]
    assert status == ["done", "done", "interrupted"] + ["pending"] * 5
    assert rows(spec)[2]["exit_code"] == "130"
    runner = FakeRunner()
    assert run_sweep(spec, runner, tty=False, figures=False) == 0
    assert [p.name for p in runner.calls] == [c.name for c in spec.cells()[2:]]


def test_progress_eta_comes_from_the_mean_cell_time() -> None:
    progress = SweepProgress(total=10, prior_cell_s=100.0, tty=False)
    progress.skipped(4)
    assert progress.eta_s() == pytest.approx(600.0)
    progress.end(30.0)
    progress.end(50.0)
    assert progress.eta_s() == pytest.approx(4 * 40.0)
    assert clock_text(59.6) == "1:00" and clock_text(3725) == "1:02:05"


def test_a_cells_network_faults_give_its_slowest_recovery() -> None:
    doc = {"min_separation_m": 0.5,
           "net_faults": [{"recovery_s": 3.0}, {"recovery_s": 7.5}]}
    picked = pick_metrics(doc)
    assert picked[RECOVERY] == 7.5 and picked["min_separation_m"] == 0.5
    doc["net_faults"].append({"recovery_s": None})  # one never came back
    assert pick_metrics(doc)[RECOVERY] is None
    assert RECOVERY not in pick_metrics({"min_separation_m": 0.5})


def test_a_table_with_and_without_network_faults(tmp_path: Path) -> None:
    grid = {"fault": ["none", "4:partition:1,2|3,4:2", "4:isolate:follower-1:2"]}
    spec = parse_sweep(doc(grid=grid), tmp_path / "s.toml")
    rows = [Row(c, CellState("done", 0, 1.0, {"min_separation_m": 2.0,
                                                  **({RECOVERY: 4.0} if k else {})}))
            for k, c in enumerate(spec.cells())]
    cols = columns(spec, rows)
    assert RECOVERY in cols
    table = [row_values(spec, r, cols) for r in rows]
    assert [t[RECOVERY] for t in table] == ["", *["4"] * (len(rows) - 1)]
    assert "| 4 |" in markdown(spec, rows, cols, table)
