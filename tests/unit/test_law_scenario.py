"""A scenario's `[law]`: a shipped law or the user's class, checked when the scenario loads;
each bad law is one error line naming the field, before any process starts."""

from __future__ import annotations

import argparse
import ast
import logging
import subprocess
import sys
import time
from pathlib import Path

import pytest

from agents.law.paper import PaperLaw
from agents.loading.scenario_file import load_scenario, shipped_text
from agents.scenario.law import pinned_law
from agents.shell.law_args import (
    LawOptions,
    add_law_arguments,
    apply_law_arguments,
    law_overrides,
    toml_value,
)
from deploy.cli import main
from errors import ScenarioError

pytestmark = pytest.mark.timeout(120)

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "simple_law"
PAPER = shipped_text("paper")

# A law module written next to the scenario, by the test: what it defines.
GOOD_LAW = """
from agents.law.interface import Law, Output, ScenarioError

class Still(Law):
    name = "still"

    def __init__(self, gain=1.0):
        self.gain = gain

    @classmethod
    def from_params(cls, table, scenario):
        for key, value in table.items():
            if key != "gain":
                raise ScenarioError(f"law.{key}", "unknown parameter")
            if not isinstance(value, (int, float)) or value <= 0:
                raise ScenarioError("law.gain", f"must be > 0, got {value!r}")
        return cls(**table)

    def start(self, setup):
        return None

    def step(self, state, inputs):
        return state, Output(0j, 0j, 0j, {})
"""
NO_STEP = """
from agents.law.interface import Law

class Still(Law):
    def start(self, setup):
        return None
"""
RAISES = GOOD_LAW.replace("return cls(**table)", "return cls(**table) if False else 1 / 0")


def scenario_with(folder: Path, law_table: str, module: str | None = None,
                  name: str = "mylaw") -> Path:
    """The paper's case with `law_table` appended, in `folder`, with `name`.py = `module`
    (`name` replacing "mylaw" in the table: a module imported once stays imported, so
    each test names its own)."""
    folder.mkdir(parents=True, exist_ok=True)
    if module is not None:
        (folder / f"{name}.py").write_text(module)
    path = folder / "case.toml"
    path.write_text(PAPER + "\n" + law_table.replace("mylaw", name) + "\n")
    return path


def test_absent_law_is_the_papers() -> None:
    law = load_scenario("paper").law
    assert law.is_paper and law.ref == "paper" and law.params == ()


def test_own_law_imports_from_the_scenarios_folder_with_its_parameters(tmp_path: Path) -> None:
    path = scenario_with(tmp_path / "a", '[law]\nmodule = "mylaw:Still"\ngain = 2', GOOD_LAW,
                         "ownlaw")
    law = load_scenario(path).law
    assert law.module == "ownlaw:Still" and law.folder == str(path.parent)
    assert law.params == (("gain", 2),) and not law.is_paper


def test_a_folder_may_lead_the_module_relative_to_the_file(tmp_path: Path) -> None:
    (tmp_path / "laws").mkdir()
    (tmp_path / "laws" / "farlaw.py").write_text(GOOD_LAW)
    path = scenario_with(tmp_path / "cases", '[law]\nmodule = "../laws/farlaw:Still"')
    assert load_scenario(path).law.folder == str(tmp_path / "laws")


def test_a_law_module_shadowed_by_one_imported_before_is_an_error(tmp_path: Path) -> None:
    scenario_with(tmp_path / "a", '[law]\nmodule = "twinlaw:Still"', None)
    (tmp_path / "a" / "twinlaw.py").write_text(GOOD_LAW)
    load_scenario(tmp_path / "a" / "case.toml")
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "twinlaw.py").write_text(GOOD_LAW)
    (tmp_path / "b" / "case.toml").write_text((tmp_path / "a" / "case.toml").read_text())
    with pytest.raises(ScenarioError, match="shadowed"):
        load_scenario(tmp_path / "b" / "case.toml")
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "json.py").write_text(GOOD_LAW)  # the standard library's is loaded
    (tmp_path / "c" / "case.toml").write_text(PAPER + '[law]\nmodule = "json:Still"\n')
    with pytest.raises(ScenarioError, match="shadowed"):
        load_scenario(tmp_path / "c" / "case.toml")


# (what is broken, [law] table, module text or None, the field the error names, a word)
BAD = [
    ("unknown shipped", '[law]\nname = "papr"', None, "law.name", "papr"),
    ("name and module", '[law]\nname = "paper"\nmodule = "mylaw:Still"', GOOD_LAW,
     "law.module", "not both"),
    ("module malformed", '[law]\nmodule = "mylaw.Still"', GOOD_LAW, "law.module",
     "package.module:Class"),
    ("module missing", '[law]\nmodule = "nolaw:Still"', None, "law.module", "nolaw"),
    ("module broken", '[law]\nmodule = "mylaw:Still"', "def (:\n", "law.module", "SyntaxError"),
    ("module raises", '[law]\nmodule = "mylaw:Still"', "raise RuntimeError('boom')",
     "law.module", "boom"),
    ("class missing", '[law]\nmodule = "mylaw:Gone"', GOOD_LAW, "law.module", "Gone"),
    ("not a law", '[law]\nmodule = "mylaw:Path"', "from pathlib import Path", "law.module",
     "not a class derived"),
    ("no step", '[law]\nmodule = "mylaw:Still"', NO_STEP, "law.module", "step"),
    ("unknown parameter", '[law]\nmodule = "mylaw:Still"\nspeed = 1', GOOD_LAW, "law.speed",
     "unknown"),
    ("bad parameter", '[law]\nmodule = "mylaw:Still"\ngain = -1', GOOD_LAW, "law.gain", "-1"),
    ("from_params raises", '[law]\nmodule = "mylaw:Still"', RAISES, "law", "ZeroDivision"),
    ("paper takes none", '[law]\nname = "paper"\nk_p = 1', None, "law.k_p", "[gains]"),
    ("name not text", "[law]\nname = 3", None, "law.name", "string"),
]


@pytest.mark.parametrize(("what", "table", "module", "field", "word"), BAD,
                         ids=[b[0] for b in BAD])
def test_a_bad_law_is_a_scenario_error_naming_the_field(
        what: str, table: str, module: str | None, field: str, word: str,
        tmp_path: Path) -> None:
    # Each case its own folder and module name: a module imported once stays imported.
    module_name = "law_" + what.replace(" ", "_")
    table = table.replace("mylaw", module_name)
    folder = tmp_path / "case"
    path = scenario_with(folder, table)
    if module is not None:
        (folder / f"{module_name}.py").write_text(module.replace("mylaw", module_name))
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    assert caught.value.field == field, (what, str(caught.value))
    assert word in str(caught.value), (what, str(caught.value))


def test_simulate_with_a_bad_law_is_one_line_and_exit_code_2(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = scenario_with(tmp_path, '[law]\nmodule = "mylaw:Still"\nspeed = 1', GOOD_LAW,
                         "cli_law")
    with caplog.at_level(logging.ERROR):
        code = main(["simulate", str(path), "--out", str(tmp_path / "out")])
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert code == 2 and len(errors) == 1 and "law.speed" in errors[0]
    assert not (tmp_path / "out").exists()


@pytest.mark.realtime
@pytest.mark.parametrize("command", ["simulate", "run"])
def test_a_bad_law_stops_the_command_before_any_process(command: str, tmp_path: Path) -> None:
    path = scenario_with(tmp_path, '[law]\nmodule = "mylaw:Gone"', GOOD_LAW)
    out = tmp_path / "out"
    start = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "deploy.cli", command, str(path),
                           "--out", str(out)], capture_output=True, text=True, timeout=60)
    text = done.stderr + done.stdout
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert done.returncode == 2 and "Traceback" not in text
    assert len(lines) == 1 and "law.module" in lines[0] and "Gone" in lines[0], lines
    assert not out.exists() and time.monotonic() - start < 30  # nothing was started


def parse(*argv: str) -> LawOptions:
    parser = argparse.ArgumentParser()
    add_law_arguments(parser)
    return LawOptions.from_namespace(parser.parse_args(list(argv)))


def test_law_flags_resolve_the_folder_and_reach_a_child_unchanged(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    opts = parse("--law", "laws/mylaw:Still", "--law-param", "gain=2.5")
    assert opts == LawOptions(f"{tmp_path}/laws/mylaw:Still", (("gain", "2.5"),))
    assert parse(*law_overrides(opts)) == opts
    assert parse() == LawOptions() and law_overrides(LawOptions()) == []
    with pytest.raises(ScenarioError, match="--law-param"):
        parse("--law-param", "gain")


def test_law_flags_change_the_scenarios_law_which_checks_them(tmp_path: Path) -> None:
    path = scenario_with(tmp_path, '[law]\nmodule = "mylaw:Still"\ngain = 2', GOOD_LAW,
                         "flag_law")
    scenario = load_scenario(path)
    again = apply_law_arguments(scenario, LawOptions(None, (("gain", "3"),)))
    assert again.law.params == (("gain", 3),) and again.law.module == "flag_law:Still"
    # Another law: the scenario's own parameters were the other law's.
    paper = apply_law_arguments(scenario, LawOptions("paper"))
    assert paper.law.is_paper and paper.law.params == ()
    with pytest.raises(ScenarioError, match=r"law\.gain"):
        apply_law_arguments(scenario, LawOptions(None, (("gain", "-3"),)))
    assert apply_law_arguments(scenario, LawOptions()) is scenario


def test_law_param_values_are_read_as_toml() -> None:
    assert toml_value("2") == 2 and toml_value("0.5") == 0.5 and toml_value("true") is True
    assert toml_value('"x y"') == "x y" and toml_value("fast") == "fast"


def test_the_example_law_loads_with_its_parameters_checked() -> None:
    scenario = load_scenario(EXAMPLE / "simple.toml")
    assert scenario.law.module == "simple_law:SimpleLaw"
    assert dict(scenario.law.params)["k_c"] == 5.0
    with pytest.raises(ScenarioError, match=r"law\.k_c"):
        apply_law_arguments(scenario, LawOptions(None, (("k_c", "0"),)))
    assert isinstance(PaperLaw.from_params({}, scenario), PaperLaw)


def test_a_copy_of_the_scenario_elsewhere_loads_the_same_law(tmp_path: Path) -> None:
    original = load_scenario(EXAMPLE / "simple.toml")
    copy = tmp_path / "copy.toml"
    copy.write_text(pinned_law((EXAMPLE / "simple.toml").read_text(), original.law))
    assert load_scenario(copy).law == original.law
    paper = (EXAMPLE.parent.parent / "agents" / "scenario" / "shipped" / "paper.toml")
    assert pinned_law(paper.read_text(), load_scenario("paper").law) == paper.read_text()
    with pytest.raises(ScenarioError, match=r"law\.module"):  # an inline table: not pinned
        pinned_law('law = { module = "simple_law:SimpleLaw" }\n', original.law)


def test_the_example_law_imports_only_the_interface_of_enclose() -> None:
    tree = ast.parse((EXAMPLE / "simple_law.py").read_text())
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    imported |= {a.name for node in ast.walk(tree) if isinstance(node, ast.Import)
                 for a in node.names}
    ours = {m for m in imported if m and m.split(".")[0] in ("agents", "transport", "deploy")}
    assert ours == {"agents.law.interface"}
    assert not {m for m in imported if m and m.split(".")[0] in ("numpy", "numba")}
