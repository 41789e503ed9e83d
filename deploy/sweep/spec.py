"""A sweep file (TOML): a grid of `enclose run` network and law flags, validated once; its
cells.  The law and its parameters as axes: deploy.sweep.laws."""

from __future__ import annotations

import itertools
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.loading.scenario_file import load_scenario
from agents.scenario.model import ESTIMATORS
from agents.scenario.net_faults import check_fault_flag
from agents.scenario.network import IMPAIRMENT_KEYS, choice, impairment
from deploy.procs.restarts import RESTART_POLICIES
from deploy.sweep.laws import check_laws, is_law_key, law_flags, law_keys, law_value
from deploy.sweep.values import Value, format_value
from deploy.sweep.weather_axes import WEATHER_KEYS, weather_value
from errors import ConfigError, ScenarioError
from transport.network_schema import LINK_PROTOCOLS, LinkImpairment

# The network flags of `enclose run`, as sweep keys (--impair-seed comes from seed0 + repeat).
# `fault` ("AT_S:ACTION:TARGET[:DURATION_S]" or "none") and `restart` sweep like them.
AXIS_KEYS: tuple[str, ...] = ("estimator", "link", *IMPAIRMENT_KEYS, "fault", "restart", "law",
                              *WEATHER_KEYS)
TOP_KEYS = ("scenario", "duration_s", "out", "repeats", "seed0", "grid", "fixed", "heatmap")


def flag(key: str) -> str:
    return "--" + key.replace("_", "-")


@dataclass(frozen=True)
class Cell:
    """One run of the sweep: the grid values (file order) and the impairment seed."""

    index: int
    values: tuple[tuple[str, Value], ...]
    seed: int

    @property
    def name(self) -> str:
        parts = [f"{k}={format_value(v)}" for k, v in self.values]
        # A law's module reference may name a folder: not a directory level here.
        return "__".join([*parts, f"seed={self.seed}"]).replace("/", "_")

    def label(self) -> str:
        return " ".join([*(f"{k}={format_value(v)}" for k, v in self.values), f"seed={self.seed}"])


@dataclass(frozen=True)
class SweepSpec:
    path: Path
    scenario: str  # shipped name, or an absolute path to a TOML file
    duration_s: float
    out: Path
    repeats: int
    seed0: int
    # Each axis: its keys (more than one when values go in pairs, "delay_ms+jitter_ms") and
    # one tuple of values per point.
    grid: tuple[tuple[tuple[str, ...], tuple[tuple[Value, ...], ...]], ...]
    fixed: tuple[tuple[str, Value], ...]
    heatmap: tuple[str, str] | None
    eps_rho_m: float = 0.0999
    eps_delta: float = 0.0199

    @property
    def axes(self) -> tuple[str, ...]:
        """Every grid key, in file order (paired keys one after the other)."""
        return tuple(k for keys, _ in self.grid for k in keys)

    def partners(self, key: str) -> tuple[str, ...]:
        """The keys that vary together with `key` (itself included)."""
        return next((keys for keys, _ in self.grid if key in keys), (key,))

    def varying(self) -> tuple[str, ...]:
        """The first key of each axis that has more than one point."""
        return tuple(keys[0] for keys, points in self.grid if len(points) > 1)

    def cells(self) -> list[Cell]:
        """The product of the grid in file order (last axis fastest), then the seeds."""
        lists = [points for _, points in self.grid]
        seeds = range(self.seed0, self.seed0 + self.repeats)
        combos = itertools.product(itertools.product(*lists), seeds)
        return [
            Cell(i, tuple(zip(self.axes, itertools.chain(*combo), strict=True)), seed)
            for i, (combo, seed) in enumerate(combos)
        ]

    def run_argv(self, cell: Cell, cell_dir: Path) -> list[str]:
        """Arguments of `enclose run` for one cell."""
        argv = ["run", self.scenario, "--duration", format_value(self.duration_s)]
        argv += ["--out", str(cell_dir)]
        for key, value in (*self.fixed, *cell.values):
            if is_law_key(key):
                argv += law_flags(self.path.parent, key, value)
            else:
                argv += [flag(key), format_value(value)]
        if ("link", "udp") in (*self.fixed, *cell.values):
            argv.append("--insecure")  # Zenoh's authenticated links (mTLS) are TCP only
        return [*argv, "--impair-seed", str(cell.seed)]


def load_sweep(path: Path, out_override: Path | None = None) -> SweepSpec:
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError("sweep", f"cannot read {path}: {exc.strerror}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("sweep", f"{path} is not valid TOML: {exc}") from exc
    return parse_sweep(doc, path.resolve(), out_override)


def parse_sweep(doc: dict[str, Any], path: Path, out_override: Path | None = None) -> SweepSpec:
    unknown = sorted(set(doc) - set(TOP_KEYS))
    if unknown:
        raise ConfigError(unknown[0], f"is not a sweep setting (known: {', '.join(TOP_KEYS)})")
    base = path.parent
    scenario_ref = _scenario(doc.get("scenario", "paper"), base)
    try:
        scenario = load_scenario(scenario_ref)
    except ScenarioError as exc:
        raise ConfigError("scenario", str(exc)) from exc
    grid = _table(law_keys(doc.get("grid", {})), "grid")
    fixed = _table(law_keys(doc.get("fixed", {})), "fixed")
    axes = tuple(_axis(key, raw) for key, raw in grid.items())
    flat = [k for keys, _ in axes for k in keys]
    twice = sorted({k for k in flat if flat.count(k) > 1} | (set(flat) & set(fixed)))
    if twice:
        raise ConfigError(f"grid.{twice[0]}", "is given more than once (grid or fixed)")
    _check_faults(axes, fixed, scenario.n, scenario.m)
    spec = SweepSpec(
        path=path,
        scenario=scenario_ref,
        duration_s=_positive(doc.get("duration_s"), "duration_s"),
        out=out_override or base / _string(doc.get("out", f"runs/sweep-{path.stem}"), "out"),
        repeats=_integer(doc.get("repeats", 1), "repeats", 1),
        seed0=_integer(doc.get("seed0", 1), "seed0", 0),
        grid=axes,
        fixed=tuple((key, _value(key, raw, f"fixed.{key}")) for key, raw in fixed.items()),
        heatmap=_heatmap(doc.get("heatmap"), tuple(keys for keys, _ in axes)),
        eps_rho_m=scenario.run.eps_rho_m,
        eps_delta=scenario.run.eps_delta,
    )
    check_laws(((*spec.fixed, *cell.values) for cell in spec.cells()), path.parent, scenario)
    return spec


def _check_faults(axes: Any, fixed: dict[str, Any], n: int, m: int) -> None:
    """Fault targets must exist in the sweep's scenario (follower-5 of 4 is an error now)."""
    for keys, points in axes:
        for k, point in enumerate(points):
            for key, value in zip(keys, point, strict=True):
                if key == "fault":
                    check_fault_flag(str(value), n, m, f"grid.{key}[{k}]")
    if "fault" in fixed:
        check_fault_flag(str(fixed["fault"]), n, m, "fixed.fault")


def _scenario(raw: Any, base: Path) -> str:
    name = _string(raw, "scenario")
    return str((base / name).resolve()) if name.endswith(".toml") else name


def _string(raw: Any, where: str) -> str:
    if not isinstance(raw, str) or not raw:
        raise ConfigError(where, f"must be a non-empty string, got {raw!r}")
    return raw


def _positive(raw: Any, where: str) -> float:
    if raw is None:
        raise ConfigError(where, "is required (seconds of each run after its start)")
    if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw):
        raise ConfigError(where, f"must be a number, got {raw!r}")
    if raw <= 0:
        raise ConfigError(where, f"must be > 0, got {raw}")
    return float(raw)


def _integer(raw: Any, where: str, minimum: int) -> int:
    if isinstance(raw, bool) or not isinstance(raw, int):
        raise ConfigError(where, f"must be an integer, got {raw!r}")
    if raw < minimum:
        raise ConfigError(where, f"must be >= {minimum}, got {raw}")
    return raw


def _table(raw: Any, where: str) -> dict[str, Any]:
    if not isinstance(raw, dict):
        raise ConfigError(where, "must be a table")
    for name in raw:
        for key in name.split("+") if where == "grid" else [name]:
            if key == "impair_seed":
                raise ConfigError(f"{where}.{key}", "comes from seed0 and repeats; set those")
            if key not in AXIS_KEYS and not is_law_key(key):
                raise ConfigError(
                    f"{where}.{name}",
                    f"{key!r} is not a flag of enclose run ({', '.join(AXIS_KEYS)}, "
                    "law.<parameter>)",
                )
    return raw


def _axis(name: str, raw: Any) -> tuple[tuple[str, ...], tuple[tuple[Value, ...], ...]]:
    """`key = [v, ...]`, or paired keys `"a+b" = [[a1, b1], [a2, b2], ...]`."""
    where, keys = f"grid.{name}", tuple(name.split("+"))
    if not isinstance(raw, list):
        raise ConfigError(where, f"must be a list of values, got {raw!r}")
    if not raw:
        raise ConfigError(where, "must not be empty")
    points = []
    for i, item in enumerate(raw):
        parts = [item] if len(keys) == 1 else item
        if not isinstance(parts, list) or len(parts) != len(keys):
            raise ConfigError(f"{where}[{i}]", f"must be a list of {len(keys)} values ({name})")
        points.append(
            tuple(_value(k, v, f"{where}[{i}]") for k, v in zip(keys, parts, strict=True))
        )
    names = [tuple(format_value(v) for v in p) for p in points]
    for i, text in enumerate(names):
        if text in names[:i]:
            raise ConfigError(f"{where}[{i}]", f"repeats the point {', '.join(text)}")
    return keys, tuple(points)


def _value(key: str, raw: Any, where: str) -> Value:
    """One value of a flag, checked as the scenario's [network] table checks it."""
    try:
        if key == "estimator":
            return choice(raw, ESTIMATORS, where)
        if key == "link":
            return choice(raw, LINK_PROTOCOLS, where)
        if key == "restart":
            return choice(raw, RESTART_POLICIES, where)
        if key == "fault":  # the format here; the follower numbers against the scenario below
            check_fault_flag(_string(raw, where), 10**6, 10**6, where)
            return str(raw)
        if is_law_key(key):
            return law_value(key, raw, where)
        if key in WEATHER_KEYS:
            return weather_value(key, raw, where)
        checked = impairment({key: raw}, "x", LinkImpairment())
    except ScenarioError as exc:
        raise ConfigError(where, exc.reason) from exc
    value = getattr(checked, key)
    return value if isinstance(value, str) else float(value)


def _heatmap(raw: Any, groups: tuple[tuple[str, ...], ...]) -> tuple[str, str] | None:
    if raw is None:
        return None
    if not isinstance(raw, list) or len(raw) != 2:
        raise ConfigError("heatmap", f"must be two grid axes, got {raw!r}")
    found = []
    for i, key in enumerate(raw):
        group = next((g for g in groups if key in g), None)
        if group is None:
            known = ", ".join(k for g in groups for k in g)
            raise ConfigError(f"heatmap[{i}]", f"{key!r} is not a grid axis ({known})")
        found.append(group)
    if found[0] == found[1]:
        raise ConfigError("heatmap", f"{raw[0]} and {raw[1]} vary together: pick two axes")
    return (raw[0], raw[1])
