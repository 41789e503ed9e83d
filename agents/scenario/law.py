"""The `[law]` table of a scenario: which law the followers fly, and its parameters.

    [law]
    name = "paper"                     # a shipped law (the default when [law] is absent)

    [law]
    module = "simple_law:SimpleLaw"    # your own: package.module:Class
    k_p = 1.5                          # the law's own parameters, in the same table

`module` is imported from the scenario file's folder; a folder may lead it
(`module = "../laws/mine:MyLaw"`), relative to the file.  `name` and `module` are the
table's own keys; every other key is a parameter of the law, which the law checks itself
(`Law.from_params`, through agents.loading.law_loader) when the scenario loads.

A law reference outside a scenario file (`enclose run --law`, a sweep's `law` axis) is
written the same way: a shipped name, or `[folder/]package.module:Class`, its folder
relative to the current directory (a flag) or to the sweep file (a sweep).
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from agents.scenario.model import LawSpec
from errors import ScenarioError

KEYS = ("name", "module")
MODULE_LINE = re.compile(r"""(?m)^(\s*module\s*=\s*)("[^"\n]*"|'[^'\n]*')""")
MODULE_REF = re.compile(
    r"(?:(?P<folder>.*)/)?(?P<module>[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*):(?P<cls>[A-Za-z_]\w*)")


def parse_law(table: dict[str, Any], base: Path | None) -> LawSpec:
    """The `[law]` table; `base`: the scenario file's folder (None: a shipped scenario,
    whose module references are relative to the current directory)."""
    name, module = table.get("name"), table.get("module")
    params = tuple((k, v) for k, v in table.items() if k not in KEYS)
    if name is not None and module is not None:
        raise ScenarioError("law.module", "give name (a shipped law) or module (your own), "
                            "not both")
    if module is not None:
        return law_from_ref(_text(module, "law.module"), base, "law.module", params,
                            module_only=True)
    return LawSpec(name=_text("paper" if name is None else name, "law.name"), params=params)


def law_from_ref(ref: str, base: Path | None, where: str,
                 params: tuple[tuple[str, Any], ...] = (), module_only: bool = False) -> LawSpec:
    """A law by reference: a shipped name, or `[folder/]package.module:Class` with its
    folder relative to `base` (None: the current directory); ScenarioError naming `where`."""
    if ":" not in ref and not module_only:
        if "/" in ref or not ref.isidentifier():
            raise ScenarioError(where, f"must be a shipped law's name or "
                                f"'package.module:Class', got {ref!r}")
        return LawSpec(name=ref, params=params)
    match = MODULE_REF.fullmatch(ref)
    if match is None:
        raise ScenarioError(where, f"must be 'package.module:Class' (a folder may lead it: "
                            f"'laws/mine:MyLaw'), got {ref!r}")
    folder = (base or Path.cwd()) / (match["folder"] or ".")
    module = f"{match['module']}:{match['cls']}"
    return LawSpec(module=module, folder=str(folder.resolve()), params=params)


def absolute_ref(spec: LawSpec) -> str:
    """`spec`'s law as a reference any process can load, wherever it runs from."""
    if spec.module is None:
        return spec.name
    return f"{spec.folder}/{spec.module}" if spec.folder else spec.module


def pinned_law(text: str, spec: LawSpec) -> str:
    """A scenario file's `text` with its `[law] module` naming its folder absolutely: what
    a copy of the file written elsewhere (deploy.hosts.host_launch) needs to load the same law.
    `spec` is the law the file was read into."""
    if spec.module is None:
        return text
    ref = absolute_ref(spec)
    pinned, count = MODULE_LINE.subn(lambda m: f"{m[1]}{json.dumps(ref)}", text, count=1)
    if count != 1:
        raise ScenarioError("law.module", "write it as a line `module = \"...\"` of a [law] "
                            "table: a copy of this scenario must point it at its folder")
    return pinned


def _text(raw: Any, where: str) -> str:
    if not isinstance(raw, str) or not raw:
        raise ScenarioError(where, f"must be a non-empty string, got {raw!r}")
    return raw
