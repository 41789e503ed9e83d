"""`enclose.simulate`, `enclose.run`, `enclose.sweep`: the commands, called from Python.

Each builds the typed options its command builds from the command line
(deploy.commands.simulate.SimulateOptions, deploy.commands.run.RunOptions,
deploy.sweep.spec.SweepSpec) and calls the same function; the result is read back from the
run directory (enclose.results.load_run), as `enclose report` would read it.

The commands' modules are imported when called: `import enclose` stays light, and the
pytest plugin imports it in every test session of a project that installs enclose.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import tomli_w

from enclose.results import Run, load_run
from enclose.scenario import Scenario
from errors import ConfigError

if TYPE_CHECKING:
    import pandas as pd

    from agents.shell.law_args import LawOptions
    from agents.shell.weather_args import WeatherOptions
    from deploy.commands.replay import FollowerReplay
    from deploy.launch.launch_options import LaunchOptions

ScenarioLike = Scenario | str | Path | None
RUN_KEYS = ("duration_s", "swarm")
LAUNCH_KEYS = ("zenoh_config", "noise_std_m", "link_timeout_s", "insecure", "restart",
               "max_restarts", "faults", "port_range", "live", "figures")
LAW_KEYS = ("law", "law_params")


def as_scenario(scenario: ScenarioLike) -> Scenario:
    """A Scenario as given, or loaded from a shipped name or TOML path (None: the paper's)."""
    return scenario if isinstance(scenario, Scenario) else Scenario.load(scenario)


def simulate(scenario: ScenarioLike = None, **overrides: Any) -> Run:
    """The closed loop integrated in lock-step (`enclose simulate`), no network.

    `overrides`: dt_s, duration_s, out (default runs/simulate-<name>), engine
    ("auto", "numba", "numpy"), estimator_dt_s, progress (a bar on a terminal),
    through_interface, figures (False: none drawn), law and law_params (`law_options`)."""
    from deploy.commands.simulate import SimulateOptions
    from deploy.commands.simulate import simulate as simulate_command

    scen = as_scenario(scenario)
    known = {f.name for f in dataclasses.fields(SimulateOptions)} - {"scenario", "json"}
    _check_keys("enclose.simulate", overrides, known | set(LAW_KEYS))
    overrides["law"] = law_options(overrides.pop("law", None), overrides.pop("law_params", None))
    out = Path(overrides.pop("out", None) or Path("runs") / f"simulate-{scen.name}").resolve()
    out.mkdir(parents=True, exist_ok=True)
    overrides.setdefault("progress", False)
    opts = SimulateOptions(scenario=scen.reference(out), out=out, **overrides)
    return load_run(out, simulate_command(opts))


def run(scenario: ScenarioLike = None, **overrides: Any) -> Run:
    """The swarm as processes on this machine over Zenoh (`enclose run`).

    `overrides` are the command's options by name: duration_s, out (default
    runs/run-<name>-<time>), swarm, insecure, noise_std_m, link_timeout_s, restart,
    max_restarts, faults (["AT_S:ACTION:TARGET[:DURATION_S]", ...]), port_range ("LO-HI"),
    zenoh_config, live (True or a deploy.launch.live_args.LiveOptions: serve the live view; default
    none), figures (False: none drawn), law and law_params (`law_options`), the network's
    (estimator, estimator_order, link, zenoh_runtime, agent_sched, impair_seed,
    latency_stamps) and its impairments
    (loss, delay_ms, ...: agents.scenario.network.IMPAIRMENT_KEYS), and the weather's
    (wind: a speed toward +x or (x, y) in m/s, gust, gps_noise: docs/weather.md)."""
    from deploy.commands.run import RunOptions
    from deploy.commands.run import run as run_command

    scen = as_scenario(scenario)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(overrides.pop("out", None) or Path("runs") / f"run-{scen.name}-{stamp}").resolve()
    out.mkdir(parents=True, exist_ok=True)
    launch = launch_options(scen.reference(out), overrides)
    given = {k: overrides[k] for k in RUN_KEYS if k in overrides}
    code = run_command(RunOptions(launch, out=out, **given))
    return load_run(out, code)


def launch_options(scenario_ref: str, overrides: Mapping[str, Any]) -> LaunchOptions:
    """deploy.launch.launch_options.LaunchOptions from `enclose.run`'s keyword overrides."""
    from agents.scenario.network import IMPAIRMENT_KEYS
    from agents.shell.network_args import NetworkOptions
    from deploy.launch.launch_options import LaunchOptions
    from deploy.launch.live_args import LiveOptions

    network_keys = {f.name for f in dataclasses.fields(NetworkOptions)} - {"impairment",
                                                                           "weather"}
    _check_keys("enclose.run", overrides, {*RUN_KEYS, *LAUNCH_KEYS, *LAW_KEYS, *network_keys,
                                           *IMPAIRMENT_KEYS, *WEATHER_KEYS})
    launch = {k: overrides[k] for k in LAUNCH_KEYS if k in overrides}
    live = launch.get("live")
    launch["live"] = LiveOptions() if live is True else (live or None)
    launch["faults"] = tuple(launch.get("faults", ()))
    impairment = tuple((k, overrides[k]) for k in IMPAIRMENT_KEYS if k in overrides)
    network = NetworkOptions(**{k: overrides[k] for k in network_keys if k in overrides},
                             impairment=impairment, weather=weather_options(overrides))
    law = law_options(overrides.get("law"), overrides.get("law_params"))
    return LaunchOptions(scenario=scenario_ref, network=network, law=law, **launch)


WEATHER_KEYS = ("wind", "gust", "gps_noise")


def weather_options(overrides: Mapping[str, Any]) -> WeatherOptions:
    """--wind, --gust and --gps-noise from `enclose.run`'s keyword overrides."""
    import argparse

    from agents.shell.weather_args import WeatherOptions

    wind = overrides.get("wind")
    if isinstance(wind, list | tuple):
        wind = ",".join(str(v) for v in wind)
    return WeatherOptions.from_namespace(argparse.Namespace(
        wind=wind, gust=overrides.get("gust"), gps_noise=overrides.get("gps_noise")))


def law_options(law: str | LawOptions | None,
                params: Mapping[str, Any] | None = None) -> LawOptions:
    """The command's --law and --law-param: `law` a shipped law's name or
    "[folder/]module:Class" (from the current directory), None for the scenario's own;
    `params` override the law's parameters by name."""
    from agents.scenario.law import absolute_ref, law_from_ref
    from agents.shell.law_args import LawOptions

    if isinstance(law, LawOptions):
        return law
    ref = None if law is None else absolute_ref(law_from_ref(law, None, "law"))
    given = tuple((k, json.dumps(v)) for k, v in (params or {}).items())
    return LawOptions(ref, given)


def sweep(
    sweep_file: str | Path | None = None,
    *,
    scenario: ScenarioLike = None,
    duration_s: float | None = None,
    grid: Mapping[str, Sequence[Any]] | None = None,
    fixed: Mapping[str, Any] | None = None,
    repeats: int = 1,
    seed0: int = 1,
    out: str | Path | None = None,
    jobs: int = 1,
    cell_timeout_s: float | None = None,
    figures: bool = True,
) -> pd.DataFrame:
    """A grid of real runs (`enclose sweep`), resumable: the results table, one row a cell.

    Either a sweep file (bench/sweeps/*.toml), or its settings here: `grid` maps a network
    flag of `enclose run` to its values ({"loss": [0.0, 0.1]}); `fixed` holds flags every
    cell gets. The settings are written to <out>/sweep.toml, so that `enclose sweep
    <out>/sweep.toml` resumes or reports the same sweep."""
    import pandas as pd

    from deploy.sweep.command import run_sweep
    from deploy.sweep.spec import load_sweep

    if jobs < 1:
        raise ConfigError("jobs", f"must be >= 1, got {jobs}")
    if sweep_file is not None:
        spec = load_sweep(Path(sweep_file), Path(out).resolve() if out else None)
    else:
        where = Path(out or Path("runs") / "sweep").resolve()
        scen = as_scenario(scenario)
        doc: dict[str, Any] = {"scenario": scen.reference(where), "duration_s": duration_s,
                               "repeats": repeats, "seed0": seed0,
                               "grid": dict(grid or {}), "fixed": dict(fixed or {})}
        file = _write_sweep(where, {k: v for k, v in doc.items() if v is not None})
        spec = load_sweep(file, where)
    run_sweep(spec, timeout_s=cell_timeout_s, tty=False, figures=figures, jobs=jobs)
    return pd.read_csv(spec.out / "results.csv")


def _write_sweep(where: Path, doc: dict[str, Any]) -> Path:
    where.mkdir(parents=True, exist_ok=True)
    path = where / "sweep.toml"
    try:
        path.write_text(tomli_w.dumps(doc), encoding="utf-8")
    except (TypeError, ValueError) as exc:
        raise ConfigError("sweep", f"cannot be written as TOML: {exc}") from exc
    return path


def _check_keys(where: str, given: Mapping[str, Any], known: set[str]) -> None:
    for key in given:
        if key not in known:
            raise ConfigError(key, f"is not an option of {where} (known: "
                              f"{', '.join(sorted(known))})")


def replay(run_dir: str | Path, follower: int, law: str | None = None,
           law_params: Mapping[str, Any] | None = None, sets: Sequence[str] = (),
           figure: str | Path | None = None) -> list[FollowerReplay]:
    """`enclose replay RUN_DIR follower-K`: follower `follower`'s journals replayed, one
    `FollowerReplay` per journal (`.found.reproduced`, `.found.difference`, the series).
    With `law`, `law_params` or `sets` ("gains.k_e=4"), the first one also holds what that
    law or those parameters would have commanded on the same inputs (`.asked`, open loop)
    and the figure of the two (`.figure`).  JournalError for a damaged or foreign journal."""
    from deploy.commands.replay import ReplayOptions, replay_journals

    opts = ReplayOptions(law_options(law, law_params), tuple(sets),
                         None if figure is None else Path(figure))
    return replay_journals(Path(run_dir), follower, opts)
