"""The scenario's weather and sensing: `[wind]`, `[sensing]` and the GPS noise of `[vehicle]`.

Frozen settings only (no numpy: a follower loads a Scenario too); the processes that
act on them are agents.weather (the gust process, the noise and the sensor model).
Every table is optional: absent, the run is what it was without it.
"""

from __future__ import annotations

from dataclasses import dataclass

from agents.scenario.fields import Table, boolean, known_keys, number, positive, vec2
from errors import ScenarioError


@dataclass(frozen=True)
class WindConfig:
    """A mean wind plus first-order (Dryden-like) gusts, in the local ENU plane."""

    mean_m_s: tuple[float, float] = (0.0, 0.0)  # the air mass's mean velocity (x east, y north)
    gust_std_m_s: float = 0.0  # stationary standard deviation of each gust axis
    gust_tau_s: float = 2.0  # correlation time of the gusts
    per_vehicle: bool = True  # each vehicle its own gusts; false: one gust shared by all
    seed: int = 0
    # The wind's push on the airframe, drag_1_s x wind (an acceleration, linearised about
    # hover): the disturbance the vehicle's velocity loop rejects through its lag, leaving a
    # steady velocity error of about drag_1_s x tau_s x wind (agents.weather.gusts).
    drag_1_s: float = 1.0


@dataclass(frozen=True)
class SensingConfig:
    """Each observer's target sensor: what it misses and how late and noisy it is."""

    max_range_m: float | None = None  # None: unlimited
    detect_prob: float = 1.0
    noise_std_m: float = 0.0
    latency_s: float = 0.0
    # Measure range and bearing from the observer's own noisy (GPS) position, as a real
    # on-board sensor does, instead of adding noise to the target's true position.
    range_bearing: bool = False
    seed: int = 0

    @property
    def is_perfect(self) -> bool:
        return (self.max_range_m is None and self.detect_prob >= 1.0
                and self.noise_std_m == 0.0 and self.latency_s == 0.0 and not self.range_bearing)


def non_negative(t: Table, key: str, path: str, default: float) -> float:
    value = number(t, key, path, default)
    if value < 0.0:
        raise ScenarioError(f"{path}.{key}", f"must be >= 0, got {value}")
    return value


def probability(t: Table, key: str, path: str, default: float) -> float:
    value = number(t, key, path, default)
    if not 0.0 <= value <= 1.0:
        raise ScenarioError(f"{path}.{key}", f"must be within [0, 1], got {value}")
    return value


def seed_of(t: Table, path: str, key: str = "seed") -> int:
    seed = t.get(key, 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ScenarioError(f"{path}.{key}", f"must be a non-negative integer, got {seed!r}")
    return seed


def parse_wind(t: Table | None, path: str = "wind") -> WindConfig | None:
    """The `[wind]` table, or None when the scenario has none."""
    if t is None:
        return None
    if not isinstance(t, dict):
        raise ScenarioError(path, "must be a table")
    d = WindConfig()
    known_keys(t, d.__dataclass_fields__, path)
    return WindConfig(
        mean_m_s=vec2(t.get("mean_m_s", [0.0, 0.0]), f"{path}.mean_m_s"),
        gust_std_m_s=non_negative(t, "gust_std_m_s", path, d.gust_std_m_s),
        gust_tau_s=positive(t, "gust_tau_s", path, d.gust_tau_s),
        per_vehicle=boolean(t, "per_vehicle", path, d.per_vehicle),
        seed=seed_of(t, path),
        drag_1_s=non_negative(t, "drag_1_s", path, d.drag_1_s),
    )


def parse_sensing(t: Table | None) -> SensingConfig | None:
    """The `[sensing]` table, or None when the scenario has none."""
    if t is None:
        return None
    if not isinstance(t, dict):
        raise ScenarioError("sensing", "must be a table")
    d = SensingConfig()
    known_keys(t, d.__dataclass_fields__, "sensing")
    return SensingConfig(
        max_range_m=None if "max_range_m" not in t else positive(t, "max_range_m", "sensing"),
        detect_prob=probability(t, "detect_prob", "sensing", d.detect_prob),
        noise_std_m=non_negative(t, "noise_std_m", "sensing", d.noise_std_m),
        latency_s=non_negative(t, "latency_s", "sensing", d.latency_s),
        range_bearing=boolean(t, "range_bearing", "sensing", d.range_bearing),
        seed=seed_of(t, "sensing"),
    )
