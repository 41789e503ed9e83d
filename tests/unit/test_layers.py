"""Layering: transport is the innermost layer and imports nothing of agents/."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

TRANSPORT = Path(__file__).parents[2] / "transport"


def imported_modules(tree: ast.AST) -> list[str]:
    """Every module an `import`, `from ... import` or `import_module("...")` names,
    wherever it stands (functions, TYPE_CHECKING blocks included)."""
    names: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.append(node.module)
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(
                node.func, "id", None)) == "import_module" and node.args:
            first = node.args[0]
            if isinstance(first, ast.Constant) and isinstance(first.value, str):
                names.append(first.value)
    return names


def agents_imports(source: str) -> list[str]:
    return [m for m in imported_modules(ast.parse(source))
            if m == "agents" or m.startswith("agents.")]


def test_the_check_sees_every_form_of_import() -> None:
    source = (
        "import agents.scenario.model\n"
        "from agents import phases\n"
        "def f():\n    from agents.loading.scenario_file import load_scenario\n"
        "if TYPE_CHECKING:\n    import agents\n"
        "importlib.import_module('agents.follower')\n"
        "import agentsx\nfrom errors import ConfigError\n"
    )
    assert sorted(agents_imports(source)) == sorted(
        ["agents.scenario.model", "agents", "agents.loading.scenario_file", "agents",
         "agents.follower"]
    )


@pytest.mark.parametrize(
    "path", sorted(TRANSPORT.rglob("*.py")), ids=lambda p: str(p.relative_to(TRANSPORT))
)
def test_transport_imports_nothing_of_agents(path: Path) -> None:
    assert agents_imports(path.read_text(encoding="utf-8")) == [], path


def test_transport_has_modules_to_check() -> None:
    assert len(list(TRANSPORT.rglob("*.py"))) > 10
