"""`enclose simulate` and `enclose report` end to end on real files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from deploy.cli import main

METRIC_KEYS = {
    "steady_from_s",
    "estimator_error_m",
    "radius_error_m",
    "angle_error",
    "settle_time_s",
    "command_jump_m_s",
}


@pytest.mark.timeout(60)
def test_simulate_writes_metrics_series_and_figures(tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert (
        main(["simulate", "--dt", "0.02", "--duration", "30", "--out", str(out), "--no-progress"])
        == 0
    )
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics.keys() >= METRIC_KEYS
    assert metrics["steady_from_s"] == 15.0
    assert metrics["radius_error_m"] < 0.0999
    header = (out / "series.csv").read_text().splitlines()[0].split(",")
    assert header[:3] == ["t_s", "f1_x_m", "f1_y_m"] and "e_delta4_e_delta" not in header
    assert "e4_e_delta" in header
    rows = (out / "series.csv").read_text().splitlines()[1:]
    assert len(rows) == 1501  # 30 s at 50 Hz plus the first sample
    for png in ("performance.png", "trajectory.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        (out / png).unlink()
    assert main(["report", str(out)]) == 0
    assert (out / "performance.png").stat().st_size > 10_000
    assert (out / "trajectory.png").stat().st_size > 10_000


@pytest.mark.timeout(60)
def test_no_figures_leaves_them_to_report(tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = ["simulate", "--dt", "0.02", "--duration", "10", "--out", str(out), "--no-progress",
            "--no-figures"]
    assert main(argv) == 0
    assert (out / "metrics.json").exists() and (out / "series.parquet").exists()
    assert not list(out.glob("*.png"))
    assert main(["report", str(out)]) == 0
    assert (out / "performance.png").stat().st_size > 10_000


@pytest.mark.realtime
@pytest.mark.timeout(60)
def test_broken_scenario_is_a_clear_error_and_exit_code(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(
        "beta_m_s = 1.0\n[pattern]\nrho_d_m = -3\n[[followers]]\npos_m=[0,0]\n"
        "[[followers]]\npos_m=[1,0]\n[[targets]]\npos_m=[0,0]\nobserved_by=[1]\n"
    )
    proc = subprocess.run(
        [sys.executable, "-m", "deploy.cli", "simulate", str(bad), "--out", str(tmp_path / "x")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert "pattern.rho_d_m" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "x").exists()


def test_report_on_a_missing_directory_fails_cleanly(tmp_path: Path) -> None:
    assert main(["report", str(tmp_path / "nothing")]) == 2
