"""`enclose sweep` end to end: real `enclose run` swarms, one after the other, and Ctrl-C."""

from __future__ import annotations

import _thread
import contextlib
import csv
import json
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from deploy.procs.interrupts import interrupts
from deploy.procs.pids import is_alive
from deploy.sweep.cell_runner import TIMEOUT_EXIT, SubprocessRunner
from deploy.sweep.command import run_sweep
from deploy.sweep.parallel import StopSignals
from deploy.sweep.spec import load_sweep
from tests.integration.runs import pid_alive, run_pids, spawned, wait_for

pytestmark = pytest.mark.integration

SWEEP = """
scenario = "paper"
duration_s = 8
out = "out"
[grid]
loss = [0.0, 0.1]
"""

# A stand-in launcher: counts the SIGINTs it gets, takes a moment to stop, exits 130.
# Its run directory: `--out DIR` as `enclose run` gets it (a parallel sweep), else argv[1].
FAKE_LAUNCHER = """
import pathlib, signal, sys, time
args = sys.argv[1:]
out = pathlib.Path(args[args.index("--out") + 1] if "--out" in args else args[0])
got = []
signal.signal(signal.SIGINT, lambda *a: got.append(1))
(out / "ready").write_text("")
give_up = time.monotonic() + 90.0  # a failed test must not leave it waiting for ever
while not got and time.monotonic() < give_up:
    time.sleep(0.02)
time.sleep(0.5)
(out / "sigints").write_text(str(len(got)))
sys.exit(130)
"""


@contextlib.contextmanager
def sweeping(sweep_file: Path, *extra: str) -> Iterator[subprocess.Popen[str]]:
    """The sweep as a subprocess; whatever happens, it and every process of its cells are gone
    after."""
    argv = [sys.executable, "-m", "deploy.cli", "sweep", str(sweep_file), *extra]
    with spawned(argv, sweep_file.parent / "out") as proc:
        yield proc


def flying_for(progress: Path, t_s: float) -> bool:
    try:
        p = json.loads(progress.read_text())
    except (OSError, ValueError):
        return False
    return bool(p.get("state") == "running" and (p.get("t_s") or 0.0) > t_s)


def results(out: Path) -> list[dict[str, str]]:
    with open(out / "results.csv", newline="") as f:
        return list(csv.DictReader(f))


def placements(out: Path) -> list[tuple[str, str]]:
    """(swarm, port range) each cell ran with."""
    docs = [json.loads(p.read_text()) for p in sorted(out.glob("*/sweep_host.json"))]
    return [(d["run_flags"][1], d["run_flags"][3]) for d in docs]


@pytest.mark.timeout(300)
def test_a_two_cell_sweep_runs_real_swarms_and_resumes_without_rerunning(tmp_path: Path) -> None:
    """Two cells side by side (--jobs 2): their own swarm names and ports, no clash."""
    sweep_file = tmp_path / "s.toml"
    sweep_file.write_text(SWEEP)
    out = tmp_path / "out"
    with sweeping(sweep_file, "--jobs", "2") as proc:
        output, _ = proc.communicate(timeout=240)
    assert proc.returncode == 0, output
    table = results(out)
    assert [(r["loss"], r["status"], r["exit_code"], r["jobs"]) for r in table] == [
        ("0", "done", "0", "2"), ("0.1", "done", "0", "2")]
    (swarm_a, ports_a), (swarm_b, ports_b) = placements(out)
    assert swarm_a != swarm_b and ports_a != ports_b
    assert all(float(r["estimator_error_m"]) > 0 for r in table)
    assert float(table[0]["delivered_ratio"]) > 0.9  # no loss on the first cell
    assert (out / "error_vs_loss.png").stat().st_size > 10_000
    assert not any(is_alive(p) for p in run_pids(out))
    t0 = time.monotonic()
    with sweeping(sweep_file) as again:
        output, _ = again.communicate(timeout=60)
    assert again.returncode == 0, output
    assert time.monotonic() - t0 < 30.0  # no swarm started
    assert "2 done already, 0 to run" in output
    assert results(out) == table


@pytest.mark.timeout(300)
def test_ctrl_c_stops_the_current_cell_in_order_and_marks_it_interrupted(tmp_path: Path) -> None:
    sweep_file = tmp_path / "s.toml"
    sweep_file.write_text(SWEEP.replace("duration_s = 8", "duration_s = 600"))
    out = tmp_path / "out"
    with sweeping(sweep_file) as proc:
        progress = out / "loss=0__seed=1" / "progress.json"
        deadline = time.monotonic() + 120
        while not flying_for(progress, 3.0):
            assert time.monotonic() < deadline and proc.poll() is None, "the cell did not start"
            time.sleep(0.2)
        proc.send_signal(signal.SIGINT)
        output, _ = proc.communicate(timeout=200)
    assert proc.returncode == 130, output
    assert [r["status"] for r in results(out)] == ["interrupted", "pending"]
    launch = json.loads((out / "loss=0__seed=1" / "launch.json").read_text())
    assert launch["processes"]["recorder"]["exit_code"] == 0  # stopped in order, not killed
    assert not any(is_alive(p) for p in run_pids(out))


@pytest.mark.timeout(60)
def test_the_runner_forwards_one_sigint_and_waits_for_the_child(tmp_path: Path) -> None:
    script = tmp_path / "launcher.py"
    script.write_text(FAKE_LAUNCHER)
    out = tmp_path / "cell"

    def interrupt_when_ready() -> None:
        if (out / "ready").exists():
            raise KeyboardInterrupt

    runner = SubprocessRunner(command=[sys.executable, str(script)], tick=interrupt_when_ready)
    with pytest.raises(KeyboardInterrupt):
        runner.run_cell([str(out)], out, timeout_s=30)
    assert (out / "sigints").read_text() == "1"  # it finished its own stop


@pytest.mark.timeout(60)
def test_a_cell_over_its_time_is_stopped_and_reported(tmp_path: Path) -> None:
    script = tmp_path / "launcher.py"
    script.write_text(FAKE_LAUNCHER)
    out = tmp_path / "cell"
    runner = SubprocessRunner(command=[sys.executable, str(script)])
    assert runner.run_cell([str(out)], out, timeout_s=2) == TIMEOUT_EXIT
    assert (out / "sigints").read_text() == "1"


@pytest.mark.timeout(60)
def test_ctrl_c_stops_every_running_cell_of_a_parallel_sweep_once(tmp_path: Path) -> None:
    script = tmp_path / "launcher.py"
    script.write_text(FAKE_LAUNCHER)
    sweep_file = tmp_path / "s.toml"
    sweep_file.write_text(SWEEP.replace("[0.0, 0.1]", "[0.0, 0.1, 0.2]"))
    spec = load_sweep(sweep_file)
    signals = StopSignals()
    runner = SubprocessRunner([sys.executable, str(script)], signals.tick, 30.0, signals.kill_now)
    cells = [spec.out / c.name for c in spec.cells()]

    def interrupt_when_both_run() -> None:
        wait_for(lambda: sum((c / "ready").exists() for c in cells) == 2, 30, "two cells")
        _thread.interrupt_main()  # what a terminal's Ctrl-C does to the sweep

    threading.Thread(target=interrupt_when_both_run, daemon=True).start()
    # As `enclose sweep` does: Ctrl-C raises even where SIGINT was inherited ignored (a
    # test runner's worker), which interrupt_main would otherwise leave unnoticed.
    with interrupts():
        code = run_sweep(spec, runner, tty=False, figures=False, jobs=2, signals=signals)
    assert code == 130
    assert [r["status"] for r in results(spec.out)] == ["interrupted", "interrupted", "pending"]
    assert [(c / "sigints").read_text() for c in cells[:2]] == ["1", "1"]


@pytest.mark.timeout(300)
def test_a_sweep_on_a_local_two_worker_dask_cluster(tmp_path: Path) -> None:
    """`--cluster`: cells as Dask tasks on two workers (127.0.0.1 only); outputs come back
    over the wire into the sweep folder, without the runs' keys."""
    import dask
    from distributed import LocalCluster

    sweep_file = tmp_path / "s.toml"
    sweep_file.write_text(SWEEP)
    out = tmp_path / "out"
    before = set(Path(tempfile.gettempdir()).glob("enclose-cell-*"))
    with dask.config.set({"temporary-directory": str(tmp_path / "dask")}), LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
        dashboard_address=None,
    ) as cluster:
        with sweeping(sweep_file, "--cluster", cluster.scheduler_address) as proc:
            output, _ = proc.communicate(timeout=240)
        workers = [w.pid for w in cluster.workers.values()]
    assert proc.returncode == 0, output
    table = results(out)
    assert [(r["loss"], r["status"], r["jobs"]) for r in table] == [
        ("0", "done", "2"), ("0.1", "done", "2")]
    assert all(float(r["estimator_error_m"]) > 0 and r["host"] for r in table)
    for cell in out.iterdir():
        if cell.is_dir():
            assert (cell / "recording.mcap").stat().st_size > 0
            assert not (cell / "credentials").exists()
    assert len({swarm for swarm, _ in placements(out)}) == 2
    assert not any(is_alive(p) for p in run_pids(out))
    assert all(not pid_alive(pid) for pid in workers)
    assert set(Path(tempfile.gettempdir()).glob("enclose-cell-*")) <= before
