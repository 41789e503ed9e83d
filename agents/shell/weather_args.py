"""Command-line overrides of the weather (`[wind]`, `[vehicle] gps_noise_std_m`), for
`enclose run`, `enclose simulate`, a sweep's axes and every process a run starts: the
flags, their typed `WeatherOptions`, and how they change a scenario.

`--wind SPEED` (toward +x, east) or `--wind X,Y` sets the mean wind in m/s, `--gust STD`
the gusts' standard deviation in m/s, `--gps-noise STD` the vehicles' GPS noise in m.
Absent, the scenario's own tables apply; given, a scenario without `[wind]` gets one with
its other settings at their defaults (agents.scenario.weather_tables).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass

from agents.scenario.model import Scenario
from agents.scenario.weather_tables import WindConfig
from errors import ScenarioError


def add_weather_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("weather (overrides the scenario's [wind] and GPS noise)")
    g.add_argument("--wind", default=None, metavar="SPEED|X,Y",
                   help="mean wind in m/s: a speed toward +x (east), or its x,y components")
    g.add_argument("--gust", default=None, metavar="STD_M_S",
                   help="standard deviation of the first-order gusts, m/s")
    g.add_argument("--gps-noise", default=None, metavar="STD_M",
                   help="std of the noise on each vehicle's reported position, m")


@dataclass(frozen=True)
class WeatherOptions:
    """The weather flags given (None: the scenario's own setting)."""

    wind: tuple[float, float] | None = None
    gust: float | None = None
    gps_noise: float | None = None

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> WeatherOptions:
        wind = getattr(args, "wind", None)
        gust, gps = getattr(args, "gust", None), getattr(args, "gps_noise", None)
        return cls(None if wind is None else parse_wind_flag(str(wind)),
                   None if gust is None else _amount(str(gust), "--gust"),
                   None if gps is None else _amount(str(gps), "--gps-noise"))

    @property
    def given(self) -> bool:
        return self.wind is not None or self.gust is not None or self.gps_noise is not None


def parse_wind_flag(text: str) -> tuple[float, float]:
    parts = text.split(",")
    if len(parts) not in (1, 2):
        raise ScenarioError("--wind", f"expected SPEED or X,Y in m/s, got {text!r}")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise ScenarioError("--wind", f"expected SPEED or X,Y in m/s, got {text!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise ScenarioError("--wind", f"must be finite, got {text!r}")
    return (values[0], 0.0) if len(values) == 1 else (values[0], values[1])


def _amount(text: str, flag: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ScenarioError(flag, f"must be a number, got {text!r}") from None
    if not math.isfinite(value) or value < 0.0:
        raise ScenarioError(flag, f"must be >= 0, got {text!r}")
    return value


def weather_overrides(opts: WeatherOptions) -> list[str]:
    """The flags given, as argv for a child process."""
    argv = [] if opts.wind is None else ["--wind", f"{opts.wind[0]!r},{opts.wind[1]!r}"]
    argv += [] if opts.gust is None else ["--gust", repr(opts.gust)]
    return argv + ([] if opts.gps_noise is None else ["--gps-noise", repr(opts.gps_noise)])


def apply_weather_arguments(scenario: Scenario, opts: WeatherOptions) -> Scenario:
    """`scenario` with the flags applied; itself when none was given."""
    if not opts.given:
        return scenario
    if opts.wind is not None or opts.gust is not None:
        wind = scenario.wind or WindConfig()
        if opts.wind is not None:
            wind = dataclasses.replace(wind, mean_m_s=opts.wind)
        if opts.gust is not None:
            wind = dataclasses.replace(wind, gust_std_m_s=opts.gust)
        scenario = dataclasses.replace(scenario, wind=wind)
    if opts.gps_noise is not None:
        vehicle = dataclasses.replace(scenario.vehicle, gps_noise_std_m=opts.gps_noise)
        scenario = dataclasses.replace(scenario, vehicle=vehicle)
    return scenario
