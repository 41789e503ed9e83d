"""enclose as a library on real processes: a networked paper run through `enclose.run` (by
the enclose_swarm fixture) read back as a `Run`; the simulator handle stops its process."""

from __future__ import annotations

import os

import pytest

import enclose
from enclose.simulator import running_sim

pytest_plugins = ("enclose.testing",)
pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]


@pytest.mark.enclose_swarm(scenario="paper", duration_s=10.0)
def test_networked_paper_run_reads_back_whole(enclose_swarm: enclose.Run) -> None:
    run = enclose_swarm
    assert run.exit_code == 0, run.verdict.processes
    assert run.kind == "networked"
    assert run.verdict.error is None
    assert set(run.metrics) >= {"radius_error_m", "angle_error", "estimator_error_m"}
    series = run.series
    assert series.index.name == "t_s" and series.index[-1] > 8.0
    assert {"f1_x_m", "e4_e_rho_m"} <= set(series.columns)
    assert not run.links.empty
    assert {"metrics", "series", "launch", "recording", "performance"} <= set(run.paths)
    assert set(run.launch["processes"]) >= {"sim", "recorder", "follower-0", "target-1"}
    assert run.launch["enclose_version"] == run.metrics["enclose_version"] == enclose.__version__
    again = enclose.load_run(run.run_dir)  # the same directory read from scratch
    assert again.metrics == run.metrics and again.exit_code is None


def test_running_sim_stops_its_process_by_pid() -> None:
    with running_sim(vehicles=3) as sim:
        pid = sim.pid
        os.kill(pid, 0)  # running
        assert [v.sysid for v in sim.vehicles] == [1, 2, 3]
        assert len({v.listen_port for v in sim.vehicles} | {v.send_port for v in sim.vehicles}) == 6
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)
    assert "sim stopped:" in sim.output()  # it exited on SIGTERM, writing its counts
