"""Load a scenario from TOML and validate it once; every error names its field.

The loader and the assembly of a `Scenario`; each table is parsed in
agents.scenario.tables, each field read in agents.scenario.fields.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import replace
from pathlib import Path

import agents.scenario
from agents.loading.law_loader import make_law
from agents.scenario.checks import check_admissible
from agents.scenario.faults import parse_faults
from agents.scenario.fields import Table, positive, table_of, vec2
from agents.scenario.law import parse_law
from agents.scenario.model import Scenario
from agents.scenario.net_faults import parse_net_faults
from agents.scenario.network import network
from agents.scenario.tables import (
    parse_edges,
    parse_gains,
    parse_home,
    parse_pattern,
    parse_run,
    parse_successor,
    parse_targets,
    parse_vehicle,
)
from agents.scenario.weather_tables import parse_sensing, parse_wind
from errors import InadmissibleError, ScenarioError

DEFAULT_SCENARIO = "paper"


def load_scenario(source: str | Path | None = None, whole_run: bool = True) -> Scenario:
    """A shipped scenario by name (default: the paper's case) or a TOML file by path;
    `whole_run`: see `agents.scenario.checks.check_admissible`."""
    if source is None or (isinstance(source, str) and not source.endswith(".toml")):
        name = source or DEFAULT_SCENARIO
        return parse_scenario(shipped_text(name), origin=name, whole_run=whole_run)
    path = Path(source)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError("scenario", f"cannot read {path}: {exc.strerror}") from exc
    return parse_scenario(text, origin=str(path), whole_run=whole_run, base=path.parent)


def shipped_text(name: str) -> str:
    """The text of a shipped scenario.  From the package's folder when it is one (as pip
    installs it): importlib.resources costs a follower 1.4 MB of imports (tempfile,
    shutil, compressors; issue 15: <= 50 MB per follower); it serves zipped installs."""
    path = Path(agents.scenario.__file__).with_name("shipped") / f"{name}.toml"
    if path.is_file():
        return path.read_text(encoding="utf-8")
    from importlib import resources

    ref = resources.files("agents.scenario") / "shipped" / f"{name}.toml"
    if not ref.is_file():
        raise ScenarioError("scenario", f"no shipped scenario named {name!r}")
    return ref.read_text(encoding="utf-8")


def parse_scenario(text: str, origin: str = "<string>", whole_run: bool = True,
                   base: Path | None = None) -> Scenario:
    """`base`: the folder a `[law] module` is imported from (the file's; None: the
    current directory)."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError("scenario", f"{origin} is not valid TOML: {exc}") from exc
    return build_scenario(doc, default_name=Path(origin).stem, whole_run=whole_run, base=base)


def build_scenario(doc: Table, default_name: str = "scenario",
                   whole_run: bool = True, base: Path | None = None) -> Scenario:
    followers = doc.get("followers")
    if not isinstance(followers, list) or len(followers) < 2:
        raise InadmissibleError("followers", "needs at least 2 [[followers]] tables")
    f_pos = tuple(
        vec2(f.get("pos_m") if isinstance(f, dict) else f, f"followers[{k}].pos_m")
        for k, f in enumerate(followers)
    )
    n = len(f_pos)
    targets = parse_targets(doc.get("targets"), n)
    edges = parse_edges(table_of(doc, "graph"), n)
    pattern_t = table_of(doc, "pattern")
    pattern = parse_pattern(pattern_t, n)
    center = tuple(math.fsum(t.initial_pos_m[k] for t in targets) / len(targets) for k in (0, 1))
    successor = parse_successor(pattern_t, f_pos, center, n)
    run = parse_run(table_of(doc, "run"))
    net = replace(network(table_of(doc, "network"), n),
                  faults=parse_net_faults(doc.get("faults"), n, run.duration_s))
    name = doc.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise ScenarioError("name", "must be a non-empty string")
    scenario = Scenario(
        name=name,
        beta_m_s=positive(doc, "beta_m_s", ""),
        follower_pos_m=f_pos,
        targets=targets,
        edges=edges,
        successor=successor,
        pattern=pattern,
        gains=parse_gains(table_of(doc, "gains")),
        run=run,
        vehicle=parse_vehicle(table_of(doc, "vehicle")),
        home=parse_home(table_of(doc, "home")),
        network=net,
        faults=parse_faults(doc.get("faults"), n, len(targets)),
        law=parse_law(table_of(doc, "law"), base),
        wind=parse_wind(doc.get("wind")),
        sensing=parse_sensing(doc.get("sensing")),
    )
    check_admissible(scenario, whole_run)
    make_law(scenario)  # the law checks its own table now, before any process starts
    return scenario
