"""`enclose.Scenario`: a scenario as its TOML document and its checked model, for code.

A variation is the same document with some values replaced and checked again by the one
scenario reader (`agents.loading.scenario_file.build_scenario`): every error names its field.
A networked run's processes read a scenario from a file, so a variation is written as
TOML into its run directory (`Scenario.reference`), its `[law] module` pinned to the folder
it was loaded from.
"""

from __future__ import annotations

import copy
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

from agents.loading.scenario_file import DEFAULT_SCENARIO, build_scenario, shipped_text
from agents.scenario.law import absolute_ref
from agents.scenario.model import Scenario as ScenarioModel
from errors import ScenarioError

SCENARIO_FILE = "scenario.toml"  # a variation, written into the run directory it runs in


@dataclass(frozen=True)
class Scenario:
    """One enclosing experiment. `document`: its TOML tables; `model`: the checked scenario
    the controller runs; `origin`: the shipped name or file it came from ("" once changed);
    `base`: the folder a `[law] module` is imported from (the file's; None: shipped)."""

    document: Mapping[str, Any] = field(repr=False)
    model: ScenarioModel = field(repr=False)
    origin: str = ""
    base: Path | None = None

    @classmethod
    def load(cls, source: str | Path | None = None) -> Scenario:
        """A shipped scenario by name (default: the paper's case) or a TOML file by path."""
        if source is None or (isinstance(source, str) and not source.endswith(".toml")):
            name = source or DEFAULT_SCENARIO
            return cls.from_toml(shipped_text(name), origin=name)
        path = Path(source)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise ScenarioError("scenario", f"cannot read {path}: {exc.strerror}") from exc
        path = path.resolve()
        return cls.from_toml(text, origin=str(path), base=path.parent)

    @classmethod
    def from_toml(cls, text: str, origin: str = "", base: Path | None = None) -> Scenario:
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ScenarioError("scenario", f"{origin or 'text'} is not valid TOML: {exc}") from exc
        return cls.from_document(doc, origin, base)

    @classmethod
    def from_document(cls, document: Mapping[str, Any], origin: str = "",
                      base: Path | None = None) -> Scenario:
        """Checked as a file is; the name defaults to the origin's stem, as a file's does."""
        doc = copy.deepcopy(dict(document))
        model = build_scenario(doc, default_name=Path(origin).stem if origin else "scenario",
                               base=base)
        doc["name"] = model.name  # a written variation keeps the name the model has
        return cls(doc, model, origin, base)

    def replace(self, changes: Mapping[str, Any] | None = None, /, **values: Any) -> Scenario:
        """A variation: `changes` by dotted path ({"pattern.rho_d_m": 6.0,
        "followers.0.pos_m": [1.0, 2.0]}), `values` by name with "__" between levels
        (`run__duration_s=20.0`, `beta_m_s=1.5`). A value replaces what was there whole."""
        doc = copy.deepcopy(dict(self.document))
        paths = {**(changes or {}), **{k.replace("__", "."): v for k, v in values.items()}}
        for path, value in paths.items():
            _assign(doc, path, value)
        return Scenario.from_document(doc, "", self.base)

    def __repr__(self) -> str:
        return f"Scenario(name={self.name!r}, n={self.n}, m={self.m}, origin={self.origin!r})"

    @property
    def name(self) -> str:
        return self.model.name

    @property
    def n(self) -> int:
        """Followers."""
        return self.model.n

    @property
    def m(self) -> int:
        """Targets."""
        return self.model.m

    def to_toml(self) -> str:
        """The document, its `[law] module` naming its folder absolutely: the text loads the
        same law wherever it is written."""
        doc = copy.deepcopy(dict(self.document))
        law = doc.get("law")
        if self.model.law.module is not None and isinstance(law, dict):
            law["module"] = absolute_ref(self.model.law)
        try:
            return tomli_w.dumps(doc)
        except (TypeError, ValueError) as exc:
            raise ScenarioError("scenario", f"cannot be written as TOML: {exc}") from exc

    def write(self, path: Path) -> Path:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(self.to_toml(), encoding="utf-8")
        return path

    def reference(self, run_dir: Path) -> str:
        """How a command and its processes are told this scenario: the shipped name or
        file it came from, unchanged; else its TOML written into `run_dir`."""
        if self.origin:
            return self.origin
        return str(self.write(run_dir / SCENARIO_FILE).resolve())


def _assign(doc: dict[str, Any], path: str, value: Any) -> None:
    """Set doc[a][b]... for path "a.b..."; a number indexes a list ("followers.0.pos_m")."""
    keys = path.split(".")
    node: Any = doc
    for depth, key in enumerate(keys):
        last = depth == len(keys) - 1
        where = ".".join(keys[: depth + 1])
        if isinstance(node, list):
            if not key.isdigit() or int(key) >= len(node):
                raise ScenarioError(where, f"is not an index of a list of {len(node)}")
            index: Any = int(key)
        elif isinstance(node, dict):
            index = key
            if not last:
                node.setdefault(key, {})
        else:
            raise ScenarioError(where, f"{'.'.join(keys[:depth])} is a value, not a table")
        if last:
            node[index] = copy.deepcopy(value)
        else:
            node = node[index]
