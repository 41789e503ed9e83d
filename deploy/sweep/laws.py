"""The law as sweep axes: `law` (which law the followers fly) and `law.<parameter>`.

`law = ["paper", "simple_law:SimpleLaw"]` takes shipped names or module references whose
folder is relative to the sweep file; `"law.k_c" = [2.0, 5.0]` one parameter of the law
(quoted: TOML reads a bare dotted key as a table, which `law_keys` flattens the same).  A
cell runs `enclose run --law REF --law-param KEY=VALUE` (agents.shell.law_args).  Every law and
parameter combination of the grid is checked by the law itself when the sweep file is read.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from agents.scenario.law import absolute_ref, law_from_ref
from agents.scenario.model import Scenario
from agents.shell.law_args import LawOptions, apply_law_arguments
from deploy.sweep.values import Value, format_value, toml_text
from errors import ConfigError, ScenarioError

LAW_PARAM = "law."  # "law.<parameter>": one parameter of the law (--law-param)


def is_law_key(key: str) -> bool:
    return key == "law" or (key.startswith(LAW_PARAM) and key[len(LAW_PARAM):].isidentifier())


def law_keys(raw: Any) -> Any:
    """A `law` table in a grid or fixed table (TOML's reading of a bare `law.k_c = [..]`)
    as "law.k_c" keys."""
    if not isinstance(raw, dict) or not isinstance(raw.get("law"), dict):
        return raw
    flat = {k: v for k, v in raw.items() if k != "law"}
    flat.update({f"{LAW_PARAM}{k}": v for k, v in raw["law"].items()})
    return flat


def law_value(key: str, raw: Any, where: str) -> Value:
    """One value of a law axis, in its form; the law checks it with the grid (check_laws)."""
    if key == "law":
        if not isinstance(raw, str) or not raw:
            raise ConfigError(where, f"must be a law's name or module reference, got {raw!r}")
        try:
            law_from_ref(raw, None, where)
        except ScenarioError as exc:
            raise ConfigError(where, exc.reason) from None
        return raw
    if not isinstance(raw, str | int | float | bool):
        raise ConfigError(where, f"must be a number, a boolean or a string, got {raw!r}")
    return raw


def law_flags(base: Path, key: str, value: Value) -> list[str]:
    """The `enclose run` flags of one law value (a `law` folder relative to `base`)."""
    if key == "law":
        return ["--law", absolute_ref(law_from_ref(str(value), base, "law"))]
    return ["--law-param", f"{key[len(LAW_PARAM):]}={toml_text(value)}"]


def law_options(base: Path, values: Iterable[tuple[str, Value]]) -> LawOptions:
    """The law flags of a cell's values, typed as `enclose run` reads them."""
    law, params = None, []
    for key, value in values:
        if key == "law":
            law = absolute_ref(law_from_ref(str(value), base, "law"))
        elif key.startswith(LAW_PARAM):
            params.append((key[len(LAW_PARAM):], toml_text(value)))
    return LawOptions(law, tuple(params))


def check_laws(cells: Iterable[Iterable[tuple[str, Value]]], base: Path,
               scenario: Scenario) -> None:
    """Every law and parameter combination among `cells` (each cell's values, fixed ones
    included), checked by the law once each: ConfigError naming the values."""
    seen: set[LawOptions] = set()
    for values in cells:
        laws = tuple((k, v) for k, v in values if is_law_key(k))
        opts = law_options(base, laws)
        if not laws or opts in seen:
            continue
        seen.add(opts)
        try:
            apply_law_arguments(scenario, opts)
        except ScenarioError as exc:
            where = " ".join(f"{k}={format_value(v)}" for k, v in laws)
            raise ConfigError("grid", f"the cells with {where}: {exc}") from None
