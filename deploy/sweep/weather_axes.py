"""The weather's flags of `enclose run` as sweep axes (agents.shell.weather_args): `wind` (a
speed toward +x, or "x,y"), `gust` and `gps_noise`, checked as the flags check them."""

from __future__ import annotations

from typing import Any

from agents.shell.weather_args import parse_wind_flag
from deploy.sweep.values import Value
from errors import ScenarioError

WEATHER_KEYS = ("wind", "gust", "gps_noise")


def weather_value(key: str, raw: Any, where: str) -> Value:
    """One point of a weather axis (ScenarioError naming `where` when bad)."""
    if key == "wind" and isinstance(raw, str):
        parse_wind_flag(raw)
        return raw
    if isinstance(raw, bool) or not isinstance(raw, int | float):
        raise ScenarioError(where, f"{key} must be a number, got {raw!r}")
    if not raw >= 0.0 or raw == float("inf"):
        raise ScenarioError(where, f"{key} must be a finite number >= 0, got {raw!r}")
    return float(raw)
