"""enclose.Scenario: load, variations by dotted path, errors naming the field, TOML out."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from enclose import Scenario
from errors import InadmissibleError, ScenarioError

pytestmark = pytest.mark.timeout(30)


def test_load_shipped_and_from_file(tmp_path: Path) -> None:
    paper = Scenario.load()
    assert (paper.name, paper.n, paper.m, paper.origin) == ("paper", 4, 2, "paper")
    path = paper.write(tmp_path / "mine.toml")
    again = Scenario.load(path)
    assert again.origin == str(path.resolve())
    assert again.model == paper.model


def test_replace_by_dotted_path_and_by_keyword() -> None:
    paper = Scenario.load("paper")
    wide = paper.replace({"pattern.rho_d_m": 10.0, "followers.0.pos_m": [11.0, -19.0]},
                         run__duration_s=30.0, name="wide")
    assert wide.model.pattern.rho_d_m == 10.0
    assert wide.model.follower_pos_m[0] == (11.0, -19.0)
    assert wide.model.run.duration_s == 30.0
    assert (wide.name, wide.origin) == ("wide", "")
    assert paper.model.pattern.rho_d_m == 8.0  # the original is left as it was
    assert paper.document["pattern"]["rho_d_m"] == 8.0


def test_replace_checks_again_naming_the_field() -> None:
    paper = Scenario.load()
    with pytest.raises(ScenarioError) as bad:
        paper.replace({"pattern.rho_d_m": -1.0})
    assert bad.value.field == "pattern.rho_d_m"
    with pytest.raises(ScenarioError) as index:
        paper.replace({"followers.9.pos_m": [0.0, 0.0]})
    assert index.value.field == "followers.9"
    with pytest.raises(ScenarioError) as scalar:
        paper.replace({"beta_m_s.x": 1.0})
    assert scalar.value.field == "beta_m_s.x"
    with pytest.raises(InadmissibleError):
        paper.replace({"pattern.angles_deg": [90.0, 90.0, 90.0, 91.0]})


def test_variation_is_written_for_the_processes(tmp_path: Path) -> None:
    paper = Scenario.load()
    assert paper.reference(tmp_path) == "paper"  # unchanged: named as shipped
    assert not (tmp_path / "scenario.toml").exists()
    fast = paper.replace(beta_m_s=1.5)
    ref = fast.reference(tmp_path)
    assert ref == str((tmp_path / "scenario.toml").resolve())
    doc = tomllib.loads(Path(ref).read_text())
    assert doc["beta_m_s"] == 1.5 and doc["name"] == "paper"
    assert Scenario.load(ref).model == fast.model


def test_unwritable_value_is_a_scenario_error() -> None:
    odd = Scenario.load().replace(name="odd")
    doc = dict(odd.document)
    doc["extra"] = object()
    with pytest.raises(ScenarioError, match="TOML"):
        Scenario(doc, odd.model, "").to_toml()


def test_a_variation_of_a_scenario_with_its_own_law_loads_it_anywhere(tmp_path: Path) -> None:
    example = Path(__file__).resolve().parents[2] / "examples" / "simple_law" / "simple.toml"
    mine = Scenario.load(example)
    assert mine.model.law.module is not None
    assert mine.base == example.parent
    wider = mine.replace({"pattern.rho_d_m": 10.0})
    assert wider.model.law == mine.model.law  # the law still from the example's folder
    ref = wider.reference(tmp_path / "run")  # written far from the law's module
    again = Scenario.load(ref)
    assert again.model.law.folder == mine.model.law.folder
    assert again.model.law.module == mine.model.law.module
    assert again.model.pattern.rho_d_m == 10.0
