"""The parsers of a scenario file's tables: targets, graph, pattern, gains, run, vehicle, home.

Apart from the loader (agents.loading.scenario_file), which reads the file and assembles the
`Scenario` from what these return, so that each table's rules are read in one place;
`[network]` and `[[faults]]` have their own modules (agents.scenario.network,
agents.scenario.faults).
"""

from __future__ import annotations

import math
from typing import Any

from agents.scenario.fields import (
    Table,
    boolean,
    follower_numbers,
    known_keys,
    number,
    positive,
    vec2,
)
from agents.scenario.model import (
    PROFILE_KINDS,
    REBALANCE,
    Gains,
    HomeConfig,
    Pattern,
    RunConfig,
    TargetSpec,
    VehicleConfig,
    ccw_order,
    full_turn_ok,
    successor_from_order,
)
from agents.scenario.weather_tables import non_negative, seed_of
from errors import InadmissibleError, ScenarioError


def parse_targets(raw: Any, n: int) -> tuple[TargetSpec, ...]:
    if not isinstance(raw, list) or not raw:
        raise InadmissibleError("targets", "needs at least 1 [[targets]] table")
    specs = []
    for j, t in enumerate(raw):
        where = f"targets[{j}]"
        if not isinstance(t, dict):
            raise ScenarioError(where, "must be a table")
        profile = t.get("profile", "constant")
        if profile not in PROFILE_KINDS:
            raise ScenarioError(
                f"{where}.profile", f"must be one of {PROFILE_KINDS}, got {profile!r}"
            )
        observed = follower_numbers(t.get("observed_by"), f"{where}.observed_by", n)
        if not observed:
            raise InadmissibleError(
                f"{where}.observed_by", "every target must be observed by a follower"
            )
        seed = t.get("seed", j)
        if not isinstance(seed, int):
            raise ScenarioError(f"{where}.seed", f"must be an integer, got {seed!r}")
        specs.append(
            TargetSpec(
                initial_pos_m=vec2(t.get("pos_m"), f"{where}.pos_m"),
                profile=profile,
                observed_by=tuple(sorted(set(observed))),
                vel_m_s=vec2(t.get("vel_m_s", [0.0, 0.0]), f"{where}.vel_m_s"),
                center_m=vec2(t.get("center_m", [0.0, 0.0]), f"{where}.center_m"),
                omega_rad_s=number(t, "omega_rad_s", where, 0.0),
                speed_max_m_s=number(t, "speed_max_m_s", where, 0.0),
                knot_interval_s=positive(t, "knot_interval_s", where, 2.0),
                seed=seed,
            )
        )
    return tuple(specs)


def parse_edges(graph: Table, n: int) -> tuple[tuple[int, int], ...]:
    raw = graph.get("edges", [[i + 1, (i + 1) % n + 1] for i in range(n)])
    if not isinstance(raw, list):
        raise ScenarioError("graph.edges", "must be a list of [i, j] follower pairs")
    edges: set[tuple[int, int]] = set()
    for k, pair in enumerate(raw):
        if not isinstance(pair, list) or len(pair) != 2:
            raise ScenarioError(f"graph.edges[{k}]", f"must be a pair [i, j], got {pair!r}")
        i, j = follower_numbers(pair, f"graph.edges[{k}]", n)
        if i == j:
            raise InadmissibleError(f"graph.edges[{k}]", f"self-loop on follower {i + 1}")
        edges.add((min(i, j), max(i, j)))
    return tuple(sorted(edges))


def parse_pattern(t: Table, n: int) -> Pattern:
    raw = t.get("angles_deg")
    if raw is None:
        angles = tuple([2.0 * math.pi / n] * n)
    else:
        if not isinstance(raw, list) or len(raw) != n:
            raise InadmissibleError("pattern.angles_deg", f"needs one angle per follower ({n})")
        angles = tuple(
            math.radians(number({"a": a}, "a", f"pattern.angles_deg[{k}]"))
            for k, a in enumerate(raw)
        )
    for k, a in enumerate(angles):
        if a <= 0.0:
            raise InadmissibleError(f"pattern.angles_deg[{k}]", "every included angle must be > 0")
    if not full_turn_ok(angles):
        total = math.degrees(sum(angles))
        raise InadmissibleError("pattern.angles_deg", f"must sum to 360 deg, sums to {total:.6g}")
    w_d = number(t, "w_d_rad_s", "pattern", 0.2)
    if w_d <= 0.0:
        raise InadmissibleError("pattern.w_d_rad_s", f"must be > 0, got {w_d}")
    rebalance = t.get("rebalance", "scale")
    if rebalance not in REBALANCE:
        raise InadmissibleError("pattern.rebalance", f"must be one of {REBALANCE}: {rebalance!r}")
    return Pattern(
        rho_d_m=positive(t, "rho_d_m", "pattern"),
        w_d_rad_s=w_d,
        angles_rad=angles,
        rebalance=rebalance,
    )


def parse_successor(t: Table, f_pos: tuple[tuple[float, float], ...], center: tuple[float, ...],
               n: int) -> tuple[int, ...]:
    raw = t.get("order")
    if raw is None:
        return ccw_order(f_pos, center)
    order = follower_numbers(raw, "pattern.order", n)
    if sorted(order) != list(range(n)):
        raise InadmissibleError("pattern.order", "must list every follower exactly once")
    return successor_from_order(order)


MAX_LEAD_S = 1.0  # longer and the prediction is a guess: inputs are held after hold_after_s


def _share(t: Table, key: str, default: float) -> float:
    fraction = number(t, key, "gains", default)
    if not 0.0 <= fraction <= 1.0:
        raise ScenarioError(f"gains.{key}", f"must be within [0, 1], got {fraction}")
    return fraction


def parse_gains(t: Table) -> Gains:
    d = Gains()
    known_keys(t, d.__dataclass_fields__, "gains")
    special = ("step_fraction", "estimator_step_fraction", "estimator_order", "lead_s",
               "spacing_gain_age")
    names = [k for k in d.__dataclass_fields__ if k not in special]
    fraction = _share(t, "step_fraction", d.step_fraction)
    est = None if "estimator_step_fraction" not in t else _share(t, "estimator_step_fraction", 0)
    order = t.get("estimator_order", d.estimator_order)
    if isinstance(order, bool) or order not in (1, 2):
        raise ScenarioError("gains.estimator_order", f"must be 1 or 2, got {order!r}")
    lead_s = number(t, "lead_s", "gains", d.lead_s)
    if not 0.0 <= lead_s <= MAX_LEAD_S:
        raise ScenarioError("gains.lead_s", f"must be within [0, {MAX_LEAD_S:g}] s, got {lead_s}")
    gain_age = None if "spacing_gain_age" not in t else positive(t, "spacing_gain_age", "gains", 1)
    g = Gains(step_fraction=fraction, estimator_step_fraction=est, estimator_order=int(order),
              lead_s=lead_s, spacing_gain_age=gain_age,
              **{k: positive(t, k, "gains", getattr(d, k)) for k in names})
    for key in ("alpha1", "alpha2", "alpha3"):
        if getattr(g, key) < 1.0:
            raise InadmissibleError(f"gains.{key}", "must be >= 1 (the paper's p > q)")
    return g


def parse_run(t: Table) -> RunConfig:
    d = RunConfig()
    known_keys(t, d.__dataclass_fields__, "run")
    steady = t.get("steady_from_s")
    rate_hz = positive(t, "rate_hz", "run", d.rate_hz)
    est_hz = positive(t, "estimator_rate_hz", "run", rate_hz)
    ratio = est_hz / rate_hz
    if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-9:
        raise ScenarioError("run.estimator_rate_hz",
                            f"must be a whole multiple of rate_hz ({rate_hz:g}), got {est_hz:g}")
    return RunConfig(
        duration_s=positive(t, "duration_s", "run", d.duration_s),
        dt_s=positive(t, "dt_s", "run", d.dt_s),
        rate_hz=rate_hz,
        estimator_rate_hz=None if "estimator_rate_hz" not in t else est_hz,
        steady_from_s=None if steady is None else number(t, "steady_from_s", "run"),
        eps_rho_m=positive(t, "eps_rho_m", "run", d.eps_rho_m),
        eps_delta=positive(t, "eps_delta", "run", d.eps_delta),
        target_start_s=number(t, "target_start_s", "run", d.target_start_s),
        safety_distance_m=positive(t, "safety_distance_m", "run", d.safety_distance_m),
        journal=boolean(t, "journal", "run", d.journal),
    )


def parse_vehicle(t: Table) -> VehicleConfig:
    d = VehicleConfig()
    known_keys(t, d.__dataclass_fields__, "vehicle")
    flavour = t.get("flavour", d.flavour)
    if flavour not in ("px4", "ardupilot"):
        raise ScenarioError("vehicle.flavour", f"must be 'px4' or 'ardupilot', got {flavour!r}")
    fields = ("altitude_m", "tau_s", "max_speed_xy_m_s", "max_speed_z_m_s", "max_accel_m_s2")
    vals = {k: positive(t, k, "vehicle", getattr(d, k)) for k in fields}
    gps = {k: non_negative(t, k, "vehicle", getattr(d, k))
           for k in ("gps_noise_std_m", "gps_bias_walk_m_s")}
    return VehicleConfig(flavour=flavour, gps_seed=seed_of(t, "vehicle", "gps_seed"),
                         **vals, **gps)


def parse_home(t: Table) -> HomeConfig:
    d = HomeConfig()
    known_keys(t, d.__dataclass_fields__, "home")
    home = HomeConfig(**{k: number(t, k, "home", getattr(d, k)) for k in d.__dataclass_fields__})
    if not -90.0 <= home.lat_deg <= 90.0:
        raise ScenarioError("home.lat_deg", f"must be within [-90, 90], got {home.lat_deg}")
    if not -180.0 <= home.lon_deg <= 180.0:
        raise ScenarioError("home.lon_deg", f"must be within [-180, 180], got {home.lon_deg}")
    return home
