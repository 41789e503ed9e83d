"""enclose's functions without processes: options checked by name, a run directory read
back, the sweep's settings written as a sweep file, the plugin's entry point."""

from __future__ import annotations

import importlib
import json
import tomllib
from pathlib import Path
from typing import Any

import pytest

import enclose
from enclose import api
from enclose.simulator import running_sim
from errors import ConfigError

pytestmark = pytest.mark.timeout(60)
ROOT = Path(__file__).resolve().parents[2]


def test_unknown_override_names_itself() -> None:
    with pytest.raises(ConfigError) as sim:
        enclose.simulate("paper", durations=3.0)
    assert sim.value.field == "durations"
    with pytest.raises(ConfigError) as run:
        api.launch_options("paper", {"los": 0.1})
    assert run.value.field == "los"


def test_run_overrides_become_the_commands_options() -> None:
    opts = api.launch_options("paper", {"loss": 0.1, "delay_ms": 20.0, "estimator": "paper",
                                        "insecure": True, "faults": ["5:kill:follower-1"],
                                        "live": True, "duration_s": 3.0})
    assert opts.scenario == "paper" and opts.insecure
    assert dict(opts.network.impairment) == {"loss": 0.1, "delay_ms": 20.0}
    assert opts.network.estimator == "paper"
    assert opts.faults == ("5:kill:follower-1",)
    assert opts.live is not None
    assert api.launch_options("paper", {}).live is None  # no live view unless asked


def write_run_dir(folder: Path) -> Path:
    folder.mkdir()
    (folder / "metrics.json").write_text(json.dumps(
        {"radius_error_m": 0.01, "angle_error": 0.001, "estimator_error_m": 0.002}))
    (folder / "run.json").write_text(json.dumps({"name": "paper", "kind": "networked",
                                                 "eps_rho_m": 0.1, "eps_delta": 0.02}))
    (folder / "launch.json").write_text(json.dumps(
        {"events": [{"event": "died", "process": "follower-1"}, "junk"], "processes": {}}))
    (folder / "series.csv").write_text("t_s,f1_x_m\n0.0,1.0\n0.5,2.0\n")
    (folder / "links.csv").write_text("t_s,link,delivered_ratio\n1.0,follower-0>1,0.99\n")
    return folder


def test_load_run_reads_every_part(tmp_path: Path) -> None:
    run = enclose.load_run(write_run_dir(tmp_path / "r"))
    assert run.kind == "networked" and run.inside and run.exit_code is None
    assert run.series.index.name == "t_s"
    assert list(run.series["f1_x_m"]) == [1.0, 2.0]
    assert run.links["delivered_ratio"].iloc[0] == pytest.approx(0.99)
    assert run.events == [{"event": "died", "process": "follower-1"}]
    assert set(run.paths) == {"metrics", "run", "launch", "series", "links"}
    assert "inside the paper's bounds" in str(run)


def test_load_run_of_an_old_lockstep_directory(tmp_path: Path) -> None:
    old = tmp_path / "old"
    old.mkdir()
    (old / "metrics.json").write_text(json.dumps({"radius_error_m": 0.5}))
    run = enclose.load_run(old)
    assert run.kind == "lockstep" and not run.inside
    assert run.series.empty and run.links.empty and run.events == []


def test_load_run_refuses_what_is_no_run(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as missing:
        enclose.load_run(tmp_path / "nowhere")
    assert missing.value.field == "run_dir"
    with pytest.raises(ConfigError, match=r"metrics\.json"):
        enclose.load_run(tmp_path)


def test_sweep_settings_go_to_a_sweep_file(tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    seen: dict[str, Any] = {}

    def fake_run_sweep(spec: Any, **kwargs: Any) -> int:
        seen.update(spec=spec, **kwargs)
        (spec.out / "results.csv").write_text("cell,loss,radius_error_m\na,0,0.01\nb,0.1,0.02\n")
        return 0

    monkeypatch.setattr("deploy.sweep.command.run_sweep", fake_run_sweep)
    out = tmp_path / "sw"
    table = enclose.sweep(scenario=enclose.Scenario.load().replace(beta_m_s=1.5),
                          duration_s=5.0, grid={"loss": [0.0, 0.1]}, out=out, jobs=2)
    assert list(table["loss"]) == [0.0, 0.1]
    doc = tomllib.loads((out / "sweep.toml").read_text())
    assert doc["grid"] == {"loss": [0.0, 0.1]} and doc["duration_s"] == 5.0
    assert doc["scenario"] == str(out / "scenario.toml")
    assert len(seen["spec"].cells()) == 2 and seen["jobs"] == 2
    with pytest.raises(ConfigError) as jobs:
        enclose.sweep(duration_s=5.0, grid={"loss": [0.0]}, out=out, jobs=0)
    assert jobs.value.field == "jobs"


def test_plugin_is_registered_under_pytest11() -> None:
    doc = tomllib.loads((ROOT / "pyproject.toml").read_text())
    entry = doc["project"]["entry-points"]["pytest11"]
    assert entry == {"enclose.testing": "enclose.testing"}
    plugin = importlib.import_module(entry["enclose.testing"])
    assert callable(plugin.enclose_sim) and callable(plugin.enclose_swarm)
    assert "enclose*" in doc["tool"]["setuptools"]["packages"]["find"]["include"]


def test_sim_arguments_are_checked_before_any_process() -> None:
    with pytest.raises(ConfigError) as flavour, running_sim(flavour="betaflight"):
        pass
    assert flavour.value.field == "flavour"
    with pytest.raises(ConfigError) as count, running_sim(vehicles=0):
        pass
    assert count.value.field == "vehicles"


def test_version_on_the_command_line_and_in_the_package(
        capsys: pytest.CaptureFixture[str]) -> None:
    from importlib.metadata import version

    from deploy.cli import main
    from enclose_release import VERSION

    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"enclose {VERSION}"
    # Written once, in enclose_release.py: the installed metadata is read from it.
    assert enclose.__version__ == VERSION == version("enclose") != ""


def test_metrics_json_carries_the_version(tmp_path: Path) -> None:
    import numpy as np

    from agents.analysis.metrics import Metrics
    from deploy.report.rundir import RunInfo, write_metrics
    from enclose_release import VERSION

    metrics = Metrics(1.0, 0.01, 0.01, 0.001, 2.0, 0.1, 10.0, 100, 3.0, 3.0, 4.0)
    info = RunInfo("paper", "lockstep", 4, 2, (1, 2, 3, 0), tuple(np.ones(4)), 8.0, 0.1,
                   0.02, 5.0)
    write_metrics(tmp_path, metrics, info, {})
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["enclose_version"] == VERSION


def test_law_overrides_become_the_commands_law_flags() -> None:
    example = ROOT / "examples" / "simple_law"
    opts = api.launch_options("paper", {"law": f"{example}/simple_law:SimpleLaw",
                                        "law_params": {"k_c": 4.0, "mode": "x"}})
    assert opts.law.law == f"{example.resolve()}/simple_law:SimpleLaw"
    assert dict(opts.law.params) == {"k_c": "4.0", "mode": '"x"'}
    assert api.launch_options("paper", {}).law.law is None  # the scenario's own law
    with pytest.raises(ConfigError) as bad:
        api.law_options("not a reference")
    assert bad.value.field == "law"
