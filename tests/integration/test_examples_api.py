"""examples/api.py, the Python API's walk-through, runs as a user runs it: a variation,
lock-step and networked, one figure from their DataFrames."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import enclose

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]
ROOT = Path(__file__).resolve().parents[2]


def test_api_example_runs_both_and_plots(tmp_path: Path) -> None:
    out = tmp_path / "api"
    proc = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "api.py"), "--duration", "10", "--out", str(out)],
        capture_output=True, text=True, timeout=280, env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert (out / "radius_error.png").stat().st_size > 10_000
    lockstep, networked = enclose.load_run(out / "lockstep"), enclose.load_run(out / "networked")
    assert (lockstep.kind, networked.kind) == ("lockstep", "networked")
    assert lockstep.info["rho_d_m"] == networked.info["rho_d_m"] == 10.0
    assert networked.verdict.error is None
