"""What the verdict says of a run's weather: the wind, the GPS noise and the sensor, as the
scenario set them (run.json), and the observations the sensor did not make (launch.json)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from agents.scenario.model import Scenario

MISSED_KEYS = ("sensing_missed", "sensing_out_of_range")


def weather_text(scenario: Scenario) -> str:
    """One line for run.json; empty when the run had no weather (run.json is then as before)."""
    parts = []
    wind = scenario.wind
    if wind is not None:
        x, y = wind.mean_m_s
        heading = math.degrees(math.atan2(y, x)) % 360.0
        shared = "per vehicle" if wind.per_vehicle else "shared"
        parts.append(f"wind {math.hypot(x, y):.3g} m/s toward {heading:.0f} deg (ENU), gusts "
                     f"{wind.gust_std_m_s:g} m/s ({wind.gust_tau_s:g} s, {shared}), seed "
                     f"{wind.seed}")
    v = scenario.vehicle
    if v.gps_noisy:
        parts.append(f"GPS noise {v.gps_noise_std_m:g} m, bias walk {v.gps_bias_walk_m_s:g} "
                     f"m/sqrt(s)")
    s = scenario.sensing
    if s is not None and not s.is_perfect:
        reach = "unlimited" if s.max_range_m is None else f"{s.max_range_m:g} m"
        form = ", range-bearing" if s.range_bearing else ""
        parts.append(f"sensing range {reach}, detection {s.detect_prob:g}, noise "
                     f"{s.noise_std_m:g} m, latency {s.latency_s:g} s{form}")
    return "; ".join(parts)


def weather_lines(info: Mapping[str, Any], launch: Mapping[str, Any]) -> tuple[str, ...]:
    """The verdict's weather lines: the settings, then what the sensor missed."""
    lines = []
    text = info.get("weather")
    if isinstance(text, str) and text:
        lines.append(text)
    windows = [f for f in launch.get("faults") or () if isinstance(f, Mapping)
               and f.get("action") == "wind"]
    if windows:  # the scenario's and --fault's, as the launcher opened them
        lines.append("gust windows: " + ", ".join(
            f"{_num(w.get('gust_std_m_s'))} m/s from {_num(w.get('at_s'))} s for "
            f"{_num(w.get('duration_s'))} s" for w in windows))
    status = launch.get("status_at_stop") or launch.get("status")
    sim = status.get("sim-0") if isinstance(status, Mapping) else None
    if isinstance(sim, Mapping) and any(k in sim for k in MISSED_KEYS):
        missed, far = (sim.get(k) if isinstance(sim.get(k), int) else 0 for k in MISSED_KEYS)
        lines.append(f"observations not made: {missed} missed, {far} out of range")
    return tuple(lines)


def _num(value: object) -> str:
    """A number from launch.json as the verdict prints it; '?' for anything else."""
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    return f"{value:g}" if ok else "?"
