"""Parallel sweeps: port slots, `--port-range`, cells side by side, mean and spread over seeds,
and the cluster runner's packing (the real cluster: tests/integration/test_sweep_run.py)."""

from __future__ import annotations

import csv
import socket
import threading
from collections.abc import Sequence
from pathlib import Path

import pytest

from deploy.cli import main
from deploy.launch.port_slots import PORTS_PER_SLOT, port_slot, slot_ports
from deploy.launch.ports import parse_port_range, ports_in_range
from deploy.sweep.cell_runner import RUN_EXTRA_FLAGS, placement_flags
from deploy.sweep.cluster import localise, pack, unpack
from deploy.sweep.command import run_sweep
from deploy.sweep.parallel import StopSignals
from deploy.sweep.spec import load_sweep
from deploy.sweep.sweep_progress import SweepProgress
from errors import DeployError
from tests.unit.test_sweep import SWEEP, FakeRunner, rows, sweep_file

pytestmark = pytest.mark.timeout(60)


def test_each_holder_gets_its_own_slot_and_a_full_machine_waits(tmp_path: Path) -> None:
    with port_slot(folder=tmp_path, slots=2) as a, port_slot(folder=tmp_path, slots=2) as b:
        assert (a.index, b.index) == (0, 1)
        assert set(a.ports).isdisjoint(b.ports) and len(a.ports) == PORTS_PER_SLOT

        def give_up() -> None:
            raise KeyboardInterrupt

        with pytest.raises(KeyboardInterrupt), port_slot(give_up, folder=tmp_path, slots=2):
            pass
    with port_slot(folder=tmp_path, slots=2) as again:
        assert again.index == 0  # released on exit
    flags = placement_flags(again)
    assert flags[:4] == ["--swarm", flags[1], "--port-range", f"{again.ports.start}-"
                         f"{again.ports.stop - 1}"] and flags[4:] == list(RUN_EXTRA_FLAGS)
    assert flags[1] != placement_flags(again)[1]  # a fresh swarm name per cell


@pytest.mark.realtime
def test_port_range_packs_the_run_and_names_what_is_wrong() -> None:
    ports = slot_ports(19)  # the last slot: least likely to be held by a sweep running now
    vehicle, adapter, endpoint = ports_in_range(ports, 6, "tcp", secure=True)
    assert (vehicle, adapter) == (ports.start, ports.start + 6)
    assert endpoint == f"tls/127.0.0.1:{ports.start + 12}"
    assert ports_in_range(ports, 6, "udp", secure=True)[2] == f"udp/127.0.0.1:{ports.start + 12}"
    assert parse_port_range("15000-15249") == range(15000, 15250)
    for bad in ("15000", "a-b", "15249-15000", "80-90", "65000-70000"):
        with pytest.raises(DeployError, match="--port-range"):
            parse_port_range(bad)
    with pytest.raises(DeployError, match="6 vehicles need 13"):
        ports_in_range(range(ports.start, ports.start + 12), 6, "tcp", secure=False)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", ports.start + 7))
        with pytest.raises(DeployError, match=f"{ports.start + 6}-{ports.start + 11} is in use"):
            ports_in_range(ports, 6, "tcp", secure=False)


class MeetingRunner(FakeRunner):
    """Every call waits until `meet` calls are running at once: passes only in parallel."""

    def __init__(self, meet: int) -> None:
        super().__init__()
        self.barrier = threading.Barrier(meet, timeout=20)

    def run_cell(self, argv: Sequence[str], out_dir: Path, timeout_s: float) -> int:
        self.barrier.wait()
        return super().run_cell(argv, out_dir, timeout_s)


@pytest.mark.realtime
def test_jobs_run_cells_side_by_side_and_give_the_sequential_table(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    seq, par = load_sweep(sweep_file(tmp_path / "a")), load_sweep(sweep_file(tmp_path / "b"))
    assert run_sweep(seq, FakeRunner(), tty=False, figures=False) == 0
    assert run_sweep(par, MeetingRunner(2), tty=False, figures=False, jobs=2) == 0
    one, two = rows(seq), rows(par)
    assert {r["jobs"] for r in one} == {"1"} and {r["jobs"] for r in two} == {"2"}
    timing = ("wall_s", "jobs", "load_1min", "host")
    assert [{k: v for k, v in r.items() if k not in timing} for r in one] == [
        {k: v for k, v in r.items() if k not in timing} for r in two]


class CountingRunner(FakeRunner):
    """FakeRunner with its calls counted under a lock (they come from several threads);
    call `interrupt_at` is a Ctrl-C: the main thread sets the stop, the cell's tick raises."""

    def __init__(self, interrupt_at: int, signals: StopSignals) -> None:
        super().__init__()
        self.lock, self.count, self.stop_at = threading.Lock(), 0, interrupt_at
        self.signals = signals

    def run_cell(self, argv: Sequence[str], out_dir: Path, timeout_s: float) -> int:
        with self.lock:
            self.count += 1
            if self.count == self.stop_at:
                self.signals.stop.set()
        self.write(argv, out_dir)  # an orderly stop leaves clean outputs
        self.signals.tick()
        return 0


@pytest.mark.realtime
def test_ctrl_c_in_a_parallel_sweep_stops_it_and_resumes(tmp_path: Path) -> None:
    spec = load_sweep(sweep_file(tmp_path))
    signals = StopSignals()
    runner = CountingRunner(3, signals)
    assert run_sweep(spec, runner, tty=False, figures=False, jobs=2, signals=signals) == 130
    status = [r["status"] for r in rows(spec)]
    # the cell whose call stopped the sweep, and maybe the one running beside it
    assert status.count("interrupted") in (1, 2), status
    assert status.count("done") + status.count("interrupted") in (3, 4), status
    assert status[4:] == ["pending"] * 4, status
    runner = FakeRunner()
    assert run_sweep(spec, runner, tty=False, figures=False, jobs=2) == 0
    assert len(runner.calls) == 8 - status.count("done")


def test_bad_jobs_is_an_error_naming_the_flag(tmp_path: Path,
                                              caplog: pytest.LogCaptureFixture) -> None:
    assert main(["sweep", str(sweep_file(tmp_path)), "--jobs", "0"]) == 2
    assert "--jobs: must be >= 1, got 0" in caplog.text


def test_repeats_give_mean_and_spread_per_grid_point(tmp_path: Path) -> None:
    text = SWEEP.replace('out = "out"', 'out = "out"\nrepeats = 3\nseed0 = 4')
    spec = load_sweep(sweep_file(tmp_path, text))
    bad = spec.cells()[2].name  # estimator=paper loss=0 delay 0, seed 6
    assert run_sweep(spec, FakeRunner(fail=[bad], links=True), tty=False, figures=False) == 1
    with open(spec.out / "results_summary.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert len(table) == 8
    first = table[0]
    assert (first["seeds"], first["done"], first["settled"]) == ("3", "2", "2")
    assert float(first["estimator_error_m_mean"]) == pytest.approx(0.01)
    assert float(first["estimator_error_m_std"]) == pytest.approx(0.0, abs=1e-12)
    lossy = next(r for r in table if r["estimator"] == "robust" and r["loss"] == "0.2")
    assert lossy["settled"] == "0" and lossy["settle_time_s_mean"] == ""
    assert float(lossy["delivered_ratio_mean"]) == pytest.approx(0.9)
    md = (spec.out / "results.md").read_text()
    assert "Mean ± standard deviation over 3 seeds" in md and "0.01 ± 0" in md


def test_cluster_cells_travel_as_tar_without_keys_and_run_in_a_local_folder(
    tmp_path: Path,
) -> None:
    cell = tmp_path / "cell"
    (cell / "logs").mkdir(parents=True)
    (cell / "metrics.json").write_text("{}")
    (cell / "logs" / "sim.log").write_text("ok")
    (cell / "credentials").mkdir()
    (cell / "credentials" / "ca.key").write_text("secret")
    back = tmp_path / "back"
    unpack(pack(cell), back)
    assert sorted(str(p.relative_to(back)) for p in back.rglob("*")) == [
        "logs", "logs/sim.log", "metrics.json"]
    argv = ["run", "/home/me/s.toml", "--duration", "8", "--out", "/home/me/sweep/c1"]
    local = localise(argv, tmp_path / "w" / "cell", tmp_path, "name = 'x'")
    assert local[1] == str(tmp_path / "s.toml")
    assert (tmp_path / "s.toml").read_text() == "name = 'x'"
    assert local[local.index("--out") + 1] == str(tmp_path / "w" / "cell")
    assert localise(["run", "paper", "--out", "x"], tmp_path / "c", tmp_path, None)[1] == "paper"


def test_progress_eta_shares_the_remaining_cells_among_the_jobs() -> None:
    progress = SweepProgress(total=10, prior_cell_s=100.0, tty=False, jobs=2)
    progress.skipped(4)
    assert progress.eta_s() == pytest.approx(300.0)
