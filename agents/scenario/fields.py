"""The field readers of a scenario file: numbers, pairs, tables, follower numbers.

Apart from the loader (agents.loading.scenario_file) and the per-table parsers
(agents.scenario.tables), which both read through them, so that a field is read and
its error worded in one place.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from typing import Any

from errors import ScenarioError

Table = dict[str, Any]


_INT_RATIO = re.compile(r"\s*([-+]?\d+)/(\d+)\s*")


def exact_float(text: str) -> float:
    """`text` ("7/3", "0.25", "1e-3") as the float nearest its exact value, as
    float(Fraction(text)) gives it.  A ratio of integers, as the shipped scenarios write
    their exponents, is divided here (int / int rounds once, exactly as Fraction does):
    importing fractions brings decimal, half a MB of RSS in every follower (issue 50)."""
    ratio = _INT_RATIO.fullmatch(text)
    if ratio is not None:
        return int(ratio[1]) / int(ratio[2])
    from fractions import Fraction  # only for what the ratio above is not

    return float(Fraction(text))


def number(table: Table, key: str, path: str, default: float | None = None) -> float:
    """A finite float; a string like "7/3" is read as an exact fraction."""
    if key not in table:
        if default is None:
            raise ScenarioError(f"{path}.{key}".lstrip("."), "is required")
        return default
    raw = table[key]
    where = f"{path}.{key}".lstrip(".")
    if isinstance(raw, bool):
        raise ScenarioError(where, f"must be a number, got {raw!r}")
    try:
        value = exact_float(raw) if isinstance(raw, str) else float(raw)
    except (TypeError, ValueError, ZeroDivisionError, OverflowError) as exc:
        raise ScenarioError(where, f"must be a number, got {raw!r}") from exc
    if not math.isfinite(value):
        raise ScenarioError(where, f"must be finite, got {raw!r}")
    return value


def positive(table: Table, key: str, path: str, default: float | None = None) -> float:
    value = number(table, key, path, default)
    if value <= 0.0:
        raise ScenarioError(f"{path}.{key}".lstrip("."), f"must be > 0, got {value}")
    return value


def boolean(table: Table, key: str, path: str, default: bool) -> bool:
    """true or false (TOML's), nothing else."""
    raw = table.get(key, default)
    if not isinstance(raw, bool):
        raise ScenarioError(f"{path}.{key}".lstrip("."), f"must be true or false, got {raw!r}")
    return raw


def vec2(raw: Any, where: str) -> tuple[float, float]:
    if not isinstance(raw, list) or len(raw) != 2:
        raise ScenarioError(where, f"must be a pair [x, y] in metres, got {raw!r}")
    x = number({"x": raw[0]}, "x", where)
    y = number({"y": raw[1]}, "y", where)
    return (x, y)


def table_of(doc: Table, key: str) -> Table:
    raw = doc.get(key, {})
    if not isinstance(raw, dict):
        raise ScenarioError(key, "must be a table")
    return raw


def known_keys(t: Table, allowed: Iterable[str], where: str) -> None:
    """A misspelt setting is an error, not a silently used default."""
    unknown = sorted(set(t) - set(allowed))
    if unknown:
        raise ScenarioError(f"{where}.{unknown[0]}", f"is not a known {where} setting")


def follower_numbers(raw: Any, where: str, n: int) -> tuple[int, ...]:
    """1-based follower numbers from the file, returned 0-based."""
    if not isinstance(raw, list) or not all(isinstance(v, int) for v in raw):
        raise ScenarioError(where, f"must be a list of follower numbers 1..{n}, got {raw!r}")
    for v in raw:
        if not 1 <= v <= n:
            raise ScenarioError(where, f"follower {v} does not exist (1..{n})")
    return tuple(v - 1 for v in raw)
