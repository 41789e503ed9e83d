"""A sweep's values (a point of an axis): their type and their text in names, tables and flags."""

from __future__ import annotations

import json

Value = str | float  # a law parameter may also be a bool (a float to the type checker)


def format_value(value: Value) -> str:
    """Stable text of a value, for directory names and tables: 50.0 -> "50", 0.1 -> "0.1"."""
    if isinstance(value, str):
        return value
    if isinstance(value, bool):
        return "true" if value else "false"
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def toml_text(value: Value) -> str:
    """`value` as a TOML value (`--law-param` reads its VALUE as one)."""
    return json.dumps(value) if isinstance(value, str) else format_value(value)
