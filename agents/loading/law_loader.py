"""A scenario's law, found and built: a shipped one by name or the user's class by module.

`make_law(scenario)` is the one way a process gets its law object: the launcher and the
lock-step engine, each follower, a sweep checking its cells.  It imports a user's module
from the folder its `[law]` table names (put first on sys.path), checks that the class
implements agents.law.interface.Law, and has the law check its own parameter table
(`from_params`).  Every failure is a ScenarioError naming the field (`law.module`,
`law.name`, `law.<parameter>`), so that a bad law stops a run before any process starts.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path
from typing import Any

from agents.law.interface import Law
from agents.law.shipped import SHIPPED
from agents.scenario.model import LawSpec, Scenario
from errors import ScenarioError

# What a law must define itself (the base class's raise NotImplementedError).
REQUIRED = ("start", "step")


def make_law(scenario: Scenario) -> Law[Any]:
    """The law of `scenario.law`, built for `scenario` by its `from_params`."""
    spec = scenario.law
    cls = law_class(spec)
    try:
        law = cls.from_params(dict(spec.params), scenario)
    except ScenarioError:
        raise
    except Exception as exc:  # the law's own check failed in a way it did not mean to
        raise ScenarioError("law", f"{spec.ref}: from_params failed: "
                            f"{type(exc).__name__}: {exc}") from None
    if not isinstance(law, Law):
        raise ScenarioError("law", f"{spec.ref}: from_params returned "
                            f"{type(law).__name__}, not a Law")
    law.declared()  # its published fields are usable (ScenarioError naming the law)
    return law


def law_class(spec: LawSpec) -> type[Law[Any]]:
    """The class `spec` names; ScenarioError naming `law.name` or `law.module`."""
    if spec.module is None:
        cls = SHIPPED.get(spec.name)
        if cls is None:
            raise ScenarioError("law.name", f"no shipped law named {spec.name!r} (shipped: "
                                f"{', '.join(sorted(SHIPPED))}; your own: module = "
                                "\"package.module:Class\")")
        return cls
    module_name, _, class_name = spec.module.partition(":")
    module = _import(module_name, spec.folder)
    cls = getattr(module, class_name, None)
    if cls is None:
        raise ScenarioError("law.module", f"module {module_name!r} has no {class_name!r}")
    if not (isinstance(cls, type) and issubclass(cls, Law)):
        raise ScenarioError("law.module", f"{spec.module} is not a class derived from "
                            "agents.law.interface.Law")
    missing = [m for m in REQUIRED if getattr(cls, m) is getattr(Law, m)]
    if missing:
        raise ScenarioError("law.module", f"{spec.module} does not implement "
                            f"{', '.join(missing)} (agents.law.interface.Law)")
    return cls


def _import(module_name: str, folder: str | None) -> Any:
    """`module_name`, imported with `folder` first on sys.path."""
    if folder is not None and folder not in sys.path:
        sys.path.insert(0, folder)
    try:
        module = importlib.import_module(module_name)
    except (Exception, SystemExit) as exc:  # whatever the user's module does on import
        where = f" from {folder}" if folder else ""
        raise ScenarioError("law.module", f"cannot import {module_name!r}{where}: "
                            f"{type(exc).__name__}: {exc}") from None
    _check_not_shadowed(module_name, folder)
    return module


def _check_not_shadowed(module_name: str, folder: str | None) -> None:
    """A module imported once stays imported: a law module in `folder` named as one
    imported before from elsewhere (the standard library's, another law's) is not the one
    the process runs, so say so rather than run the other."""
    top = module_name.partition(".")[0]
    if folder is None:
        return
    here = Path(folder)
    ours = here / f"{top}.py" if (here / f"{top}.py").exists() else here / top
    if not ours.exists():
        return  # not in the folder: an installed package, found on sys.path
    loaded = getattr(sys.modules.get(top), "__file__", None)
    if loaded is None or not Path(loaded).resolve().is_relative_to(ours.resolve()):
        raise ScenarioError("law.module", f"{top!r} in {folder} is shadowed by the module of "
                            f"that name imported before ({loaded or 'built in'}): rename yours")
