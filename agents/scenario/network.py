"""The `[network]` table of a scenario: estimator, link protocol, Zenoh runtime,
impairment (seeded)."""

from __future__ import annotations

from dataclasses import fields, replace
from typing import Any

from agents.scenario.model import ESTIMATORS
from errors import ScenarioError
from transport.network_schema import (
    AGENT_NICE_MAX,
    AGENT_SCHEDS,
    LINK_PROTOCOLS,
    LOSS_MODELS,
    ZENOH_LEASE_RANGE_S,
    ZENOH_RUNTIMES,
    LinkImpairment,
    NetworkConfig,
)

Table = dict[str, Any]
IMPAIRMENT_KEYS = tuple(f.name for f in fields(LinkImpairment))
PROBABILITIES = ("loss", "duplicate", "reorder")


def choice(value: Any, allowed: tuple[str, ...], where: str) -> str:
    if value not in allowed:
        raise ScenarioError(where, f"must be one of {allowed}, got {value!r}")
    return str(value)


def impairment(table: Table, where: str, base: LinkImpairment) -> LinkImpairment:
    """`base` with the impairment keys of `table` applied and checked."""
    updates: dict[str, Any] = {}
    for key in IMPAIRMENT_KEYS:
        if key not in table:
            continue
        raw = table[key]
        if key == "loss_model":
            updates[key] = choice(raw, LOSS_MODELS, f"{where}.{key}")
            continue
        if isinstance(raw, bool) or not isinstance(raw, int | float):
            raise ScenarioError(f"{where}.{key}", f"must be a number, got {raw!r}")
        value = float(raw)
        if key in PROBABILITIES and not 0.0 <= value <= 1.0:
            raise ScenarioError(f"{where}.{key}", f"must be a probability in [0, 1], got {value}")
        if key == "loss" and value >= 1.0:
            raise ScenarioError(f"{where}.{key}", "a link that loses everything is no link")
        if key == "burst_len" and value < 1.0:
            raise ScenarioError(f"{where}.{key}", f"must be >= 1 message, got {value}")
        if value < 0.0 or value != value or value == float("inf"):
            raise ScenarioError(f"{where}.{key}", f"must be finite and >= 0, got {value}")
        updates[key] = value
    return replace(base, **updates)


def network(table: Table, n: int) -> NetworkConfig:
    known = {"estimator", "link", "seed", "links", "zenoh_runtime", "zenoh_lease_s",
             "agent_sched", "agent_nice"}
    unknown = set(table) - set(IMPAIRMENT_KEYS) - known
    if unknown:
        raise ScenarioError(f"network.{sorted(unknown)[0]}", "is not a known network setting")
    seed = table.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ScenarioError("network.seed", f"must be an integer, got {seed!r}")
    default = impairment(table, "network", LinkImpairment())
    links = []
    raw_links = table.get("links", [])
    if not isinstance(raw_links, list):
        raise ScenarioError("network.links", "must be an array of [[network.links]] tables")
    for k, link in enumerate(raw_links):
        where = f"network.links[{k}]"
        if not isinstance(link, dict):
            raise ScenarioError(where, "must be a table with from, to and impairment keys")
        ends = []
        for end in ("from", "to"):
            v = link.get(end)
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= n:
                raise ScenarioError(
                    f"{where}.{end}", f"must be a follower number 1..{n}, got {v!r}"
                )
            ends.append(v - 1)
        links.append((ends[0], ends[1], impairment(link, where, default)))
    return NetworkConfig(
        estimator=choice(table.get("estimator", "robust"), ESTIMATORS, "network.estimator"),
        link=choice(table.get("link", "tcp"), LINK_PROTOCOLS, "network.link"),
        default=default,
        links=tuple(links),
        seed=seed,
        zenoh_runtime=choice(table.get("zenoh_runtime", "split"), ZENOH_RUNTIMES,
                             "network.zenoh_runtime"),
        agent_sched=choice(table.get("agent_sched", "normal"), AGENT_SCHEDS,
                           "network.agent_sched"),
        zenoh_lease_s=lease(table.get("zenoh_lease_s")),
        agent_nice=agent_nice(table.get("agent_nice", 0)),
    )


def agent_nice(value: Any) -> int:
    """`[network] agent_nice`: a whole nice value 0..AGENT_NICE_MAX (a weight given up)."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= AGENT_NICE_MAX:
        raise ScenarioError("network.agent_nice", f"must be a whole number 0..{AGENT_NICE_MAX}, "
                            f"got {value!r}")
    return value


def lease(value: Any) -> float | None:
    """`[network] zenoh_lease_s`: seconds within ZENOH_LEASE_RANGE_S, or absent (None)."""
    if value is None:
        return None
    lo, hi = ZENOH_LEASE_RANGE_S
    if isinstance(value, bool) or not isinstance(value, int | float) or not lo <= value <= hi:
        raise ScenarioError("network.zenoh_lease_s", f"must be seconds in {lo:g}..{hi:g}, "
                            f"got {value!r}")
    return float(value)
