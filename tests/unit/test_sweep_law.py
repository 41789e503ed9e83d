"""The law and its parameters as sweep axes: cells, their `enclose run` flags, the checks."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pytest

from agents.shell.law_args import LawOptions, add_law_arguments
from deploy.sweep.spec import load_sweep, parse_sweep
from errors import ConfigError

pytestmark = pytest.mark.timeout(60)

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "simple_law"


def sweep(grid: dict[str, Any], fixed: dict[str, Any] | None = None) -> Any:
    doc = {"scenario": "simple.toml", "duration_s": 5, "grid": grid, "fixed": fixed or {}}
    return parse_sweep(doc, EXAMPLE / "s.toml")


def law_flags(argv: list[str]) -> LawOptions:
    """What a cell's `enclose run` reads of its law flags."""
    parser = argparse.ArgumentParser()
    add_law_arguments(parser)
    known, _ = parser.parse_known_args(argv)
    return LawOptions.from_namespace(known)


def test_the_example_compares_its_law_with_the_papers_in_two_cells(tmp_path: Path) -> None:
    spec = load_sweep(EXAMPLE / "compare.toml")
    cells = spec.cells()
    assert [c.name for c in cells] == ["law=simple_law:SimpleLaw__seed=1", "law=paper__seed=1"]
    own = law_flags(spec.run_argv(cells[0], tmp_path / "a"))
    assert own == LawOptions(f"{EXAMPLE}/simple_law:SimpleLaw")
    assert law_flags(spec.run_argv(cells[1], tmp_path / "b")) == LawOptions("paper")


def test_law_parameters_are_axes_quoted_or_dotted(tmp_path: Path) -> None:
    quoted = sweep({"law.k_c": [2, 5.5]}, {"law.k_s": 0.5})
    dotted = sweep({"law": {"k_c": [2, 5.5]}}, {"law": {"k_s": 0.5}})
    assert quoted.axes == dotted.axes == ("law.k_c",)
    assert [c.name for c in quoted.cells()] == ["law.k_c=2__seed=1", "law.k_c=5.5__seed=1"]
    argv = quoted.run_argv(quoted.cells()[1], tmp_path)
    assert law_flags(argv) == LawOptions(None, (("k_s", "0.5"), ("k_c", "5.5")))


def test_a_module_with_a_folder_gives_a_flat_cell_name(tmp_path: Path) -> None:
    spec = sweep({"law": ["../simple_law/simple_law:SimpleLaw", "paper"]})
    assert "/" not in spec.cells()[0].name
    assert law_flags(spec.run_argv(spec.cells()[0], tmp_path)).law == \
        f"{EXAMPLE}/simple_law:SimpleLaw"


@pytest.mark.parametrize(("grid", "word"), [
    ({"law": ["paper"], "law.k_c": [1.0]}, "law=paper law.k_c=1"),  # the paper's takes none
    ({"law.k_x": [1.0]}, "law.k_x"),
    ({"law.k_c": [-1.0]}, "law.k_c"),
    ({"law": ["nolaw:X"]}, "law.module"),
    ({"law": ["not a law"]}, "grid.law[0]"),
    ({"law.k_c": [[1, 2]]}, "grid.law.k_c[0]"),
])
def test_a_bad_law_axis_fails_when_the_sweep_is_read(grid: dict[str, Any], word: str) -> None:
    with pytest.raises(ConfigError) as caught:
        sweep(grid)
    assert word in str(caught.value)
