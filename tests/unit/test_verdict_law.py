"""The verdict names the run's law and the law's failures in flight."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest
from rich.console import Console

from deploy.report.verdict import print_verdict, read_verdict, verdict_json

pytestmark = pytest.mark.timeout(30)


def run_dir(tmp_path: Path, law: str | None, metrics: dict[str, Any] | None = None,
            launch: dict[str, Any] | None = None) -> Path:
    base = {"steady_from_s": 1.0, "estimator_error_m": 0.01, "radius_error_m": 0.01,
            "angle_error": 0.001, "settle_time_s": 1.0}
    (tmp_path / "metrics.json").write_text(json.dumps({**base, **(metrics or {})}))
    info: dict[str, Any] = {"eps_rho_m": 0.0999, "eps_delta": 0.0199}
    if law is not None:
        info["law"] = law
    (tmp_path / "run.json").write_text(json.dumps(info))
    if launch is not None:
        (tmp_path / "launch.json").write_text(json.dumps(launch))
    return tmp_path


def text_of(path: Path) -> str:
    buf = io.StringIO()
    print_verdict(Console(file=buf, width=160, color_system=None), read_verdict(path, "run"))
    return buf.getvalue()


def statuses(**failures: int) -> dict[str, Any]:
    status = {f"follower-{i}": {"state": "running", "law_failures": n}
              for i, n in enumerate(failures.values())}
    return {"status_at_stop": {**status, "sim-0": {"state": "running"}},
            "status": {"follower-0": {"law_failures": 999}}}  # after the stop: not counted


def test_a_networked_run_names_its_law_and_counts_its_failures(tmp_path: Path) -> None:
    path = run_dir(tmp_path, "simple_law:SimpleLaw", launch=statuses(a=0, b=3, c=5))
    text = text_of(path)
    assert "law          simple_law:SimpleLaw: FAILED 8 times, the vehicle held" in text
    assert "follower-2 5" in text
    assert verdict_json(read_verdict(path, "run"))["verdict"]["law"].startswith(
        "simple_law:SimpleLaw: FAILED 8")


def test_a_law_that_never_failed_says_so(tmp_path: Path) -> None:
    assert "law          paper (no failure)" in text_of(
        run_dir(tmp_path, "paper", launch=statuses(a=0, b=0)))


def test_lock_step_runs_say_the_law_and_its_failures_from_the_metrics(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    (tmp_path / "c").mkdir()
    assert "law          paper\n" in text_of(run_dir(tmp_path / "a", "paper"))
    failed = text_of(run_dir(tmp_path / "b", "mine:Law", {"law_failures": 4}))
    assert "mine:Law: FAILED 4 times" in failed
    # A run directory from before the law was recorded: no law row.
    assert "law " not in text_of(run_dir(tmp_path / "c", None))
