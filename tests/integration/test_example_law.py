"""docs/your-law.md's commands, as written there (shortened): the example law lock-step,
networked and in its two-cell sweep against the paper's law, each judged on its figures.

The commands are read from the page's ```sh blocks, so that the page cannot rot: change a
command there and this test runs the new one."""

from __future__ import annotations

import csv
import json
import re
import shlex
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import pytest

from tests.integration.real_time import judged
from tests.integration.runs import spawned, spawned_run

pytestmark = [pytest.mark.integration, pytest.mark.timeout(600)]

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "your-law.md"
LAW = "simple_law:SimpleLaw"
# The example's figures, with room for a loaded machine: lock-step 0.026 m, 0.029 m,
# 0.0029 over 200 s; networked (60 s, 2 cores) 0.038 m, 0.053 m, 0.0032.
BOUNDS = {"estimator_error_m": 0.08, "radius_error_m": 0.0999, "angle_error": 0.0199}


def doc_commands() -> list[list[str]]:
    """Every `enclose ...` line of the page's ```sh blocks, split as a shell would."""
    blocks = re.findall(r"```sh\n(.*?)```", DOC.read_text(), flags=re.S)
    return [shlex.split(line) for block in blocks for line in block.splitlines()
            if line.startswith("enclose ")]


def command(verb: str, target: str) -> list[str]:
    """The page's `enclose <verb> <target> ...` command, as argv for this interpreter; its
    paths (relative to the repository's root, where the page runs them) made absolute."""
    found = [c for c in doc_commands() if c[1:3] == [verb, target]]
    assert found, f"docs/your-law.md has no `enclose {verb} {target}` command"
    argv = [str(ROOT / a) if (ROOT / a).exists() and not a.startswith("-") else a
            for a in found[0][1:]]
    return [sys.executable, "-m", "deploy.cli", *argv]


def finished(argv: list[str], root: Path, timeout_s: float) -> subprocess.CompletedProcess[str]:
    """`argv` to its end; it and every process of the runs under `root` gone after."""
    with spawned(argv, root) as proc:
        out, _ = proc.communicate(timeout=timeout_s)
    return subprocess.CompletedProcess(argv, proc.returncode, out, "")


def within_bounds(metrics: dict[str, Any], where: str) -> None:
    for key, bound in BOUNDS.items():
        assert metrics[key] is not None and metrics[key] < bound, (where, key, metrics[key])


def test_the_example_law_lock_step(tmp_path: Path) -> None:
    out = tmp_path / "simulate"
    argv = [*command("simulate", "examples/simple_law/simple.toml"), "--duration", "60",
            "--out", str(out), "--no-progress", "--json"]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    within_bounds(metrics, "lock-step")
    assert (metrics["law"], metrics["law_path"], metrics["law_failures"]) == (
        LAW, "interface", 0)
    assert json.loads((out / "run.json").read_text())["law"] == LAW
    assert all((out / f).exists() for f in ("series.csv", "performance.png", "trajectory.png"))


def test_the_example_law_networked(tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = [*command("run", "examples/simple_law/simple.toml"), "--duration", "20",
            "--out", str(out), "--no-live", "--json", "--link-timeout", "60"]
    with spawned_run(argv, out) as proc:
        stdout, _ = proc.communicate(timeout=300)
    done = subprocess.CompletedProcess(argv, proc.returncode, stdout, "")
    assert done.returncode == 0, done.stdout[-3000:]
    metrics = json.loads((out / "metrics.json").read_text())
    with judged(out):
        within_bounds(metrics, "networked")
    assert json.loads((out / "run.json").read_text())["law"] == LAW
    launch = json.loads((out / "launch.json").read_text())
    followers = {k: v for k, v in launch["status_at_stop"].items() if k.startswith("follower-")}
    assert len(followers) == 4 and all(v["law_failures"] == 0 for v in followers.values())
    assert (out / "recording.mcap").stat().st_size > 0
    assert "simple_law:SimpleLaw (no failure)" in done.stdout


def shortened_sweep(doc_file: Path, tmp_path: Path, duration_s: float) -> Path:
    """The page's sweep file, its runs `duration_s` long, written under `tmp_path` with
    its paths (scenario, law modules) made absolute."""
    spec = tomllib.loads(doc_file.read_text())
    base = doc_file.parent
    laws = [law if ":" not in law else f"{base}/{law}" for law in spec["grid"]["law"]]
    assert set(spec["grid"]) == {"law"}, "the page's sweep has grown axes this test ignores"
    path = tmp_path / "compare.toml"
    path.write_text(f"scenario = {json.dumps(str(base / spec['scenario']))}\n"
                    f"duration_s = {duration_s}\nout = \"out\"\n[grid]\n"
                    f"law = {json.dumps(laws)}\n")
    return path


def test_the_example_law_against_the_papers_in_a_sweep(tmp_path: Path) -> None:
    argv = command("sweep", "examples/simple_law/compare.toml")
    sweep_file = shortened_sweep(Path(argv[-1]), tmp_path, 15)
    done = finished([*argv[:-1], str(sweep_file)], tmp_path / "out", 400)
    assert done.returncode == 0, done.stdout[-3000:]
    with (tmp_path / "out" / "results.csv").open() as f:
        rows = {Path(r["law"]).name: r for r in csv.DictReader(f)}
    assert set(rows) == {LAW, "paper"} and all(r["status"] == "done" for r in rows.values())
    for law, row in rows.items():
        with judged(tmp_path / "out" / row["cell"]):
            within_bounds({k: float(row[k]) for k in BOUNDS}, law)
    # The paper's finite-time estimator is closer than plain consensus (0.010 m, 0.038 m).
    with judged(tmp_path / "out" / rows["paper"]["cell"]):
        assert float(rows["paper"]["estimator_error_m"]) < float(rows[LAW]["estimator_error_m"])
    assert (tmp_path / "out" / "error_vs_law.png").stat().st_size > 0
