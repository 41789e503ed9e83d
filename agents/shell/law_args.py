"""Command-line overrides of the `[law]` table (`--law`, `--law-param`), for `enclose run`,
`enclose simulate` and every process a run starts: the flags, their typed `LawOptions`,
and how they change a scenario.

`--law` names another law (a shipped name, or `[DIR/]package.module:Class` with DIR
relative to the current directory); the scenario's own law parameters then do not apply.
`--law-param KEY=VALUE` (repeatable) sets one parameter, VALUE read as a TOML value
(`2`, `0.5`, `true`, `"text"`; anything else is text).  A launcher hands them to its
children with the law's folder made absolute (`law_overrides`).
"""

from __future__ import annotations

import argparse
import dataclasses
import tomllib
from dataclasses import dataclass
from typing import Any

from agents.loading.law_loader import make_law
from agents.scenario.law import absolute_ref, law_from_ref
from agents.scenario.model import Scenario
from errors import ScenarioError


def add_law_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("law (overrides the scenario's [law] table)")
    g.add_argument("--law", default=None, metavar="NAME|[DIR/]MODULE:CLASS",
                   help="the law the followers fly: a shipped one (paper) or your class "
                        "(docs/your-law.md); the scenario's law parameters then do not apply")
    g.add_argument("--law-param", action="append", default=[], metavar="KEY=VALUE",
                   help="one parameter of the law, VALUE as in TOML (repeatable)")


@dataclass(frozen=True)
class LawOptions:
    """The law flags given (None / empty: the scenario's own `[law]`)."""

    law: str | None = None  # absolute reference: a shipped name or /DIR/module:Class
    params: tuple[tuple[str, str], ...] = ()  # (KEY, VALUE as given)

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> LawOptions:
        ref = getattr(args, "law", None)
        if ref is not None:  # relative to where the command was given, for any child
            ref = absolute_ref(law_from_ref(ref, None, "--law"))
        raw = getattr(args, "law_param", None) or []
        return cls(ref, tuple(_key_value(text) for text in raw))


def law_overrides(opts: LawOptions) -> list[str]:
    """The flags given, as argv for a child process."""
    argv = [] if opts.law is None else ["--law", opts.law]
    for key, value in opts.params:
        argv += ["--law-param", f"{key}={value}"]
    return argv


def apply_law_arguments(scenario: Scenario, opts: LawOptions) -> Scenario:
    """`scenario` with the flags applied to its law, which checks them (ScenarioError)."""
    if opts.law is None and not opts.params:
        return scenario
    spec = scenario.law if opts.law is None else law_from_ref(opts.law, None, "--law")
    params = dict(spec.params)
    params.update((key, toml_value(value)) for key, value in opts.params)
    scenario = dataclasses.replace(
        scenario, law=dataclasses.replace(spec, params=tuple(params.items())))
    make_law(scenario)
    return scenario


def toml_value(text: str) -> Any:
    """`text` read as a TOML value; text that is none stays text."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _key_value(text: str) -> tuple[str, str]:
    key, eq, value = text.partition("=")
    key = key.strip()
    if not eq or not key.isidentifier():
        raise ScenarioError("--law-param", f"must be KEY=VALUE, got {text!r}")
    return key, value.strip()
