"""The `[[faults]]` of a scenario: failures the launcher injects at set times, validated once.

    [[faults]]
    at_s = 30.0               # experiment time (after the start word)
    action = "kill"           # kill | pause | restart | leave | lie | wind
    target = "follower-1"     # follower-K, target-K (1-based, as in the file) | recorder | sim
    duration_s = 2.0          # pause, lie: how long (required); restart, leave: back after
    # mode = "offset"         # lie only: offset | bound | walk | stale (agents.follower.lie)

kill: SIGKILL, then the run's restart policy decides.  pause: SIGSTOP, SIGCONT after
duration_s.  restart: SIGTERM (a clean stop) and a new process at once, or after
duration_s.  leave: SIGTERM, and with duration_s it joins again after that long.
lie: the follower publishes false but valid data from its own process for duration_s (an
insider within its own rights; agents.follower.lie), started and ended by a signal.
On the command line (`enclose run --fault`, and `fault` in a sweep) a fault is
"AT_S:ACTION:TARGET[:DURATION_S[:MODE]]", e.g. "30:kill:follower-1" or
"20:lie:follower-2:30:offset"; "none" is no fault.
wind: a gust window in the simulator (target sim, the default): for duration_s the gusts
have the strength gust_std_m_s (m/s) instead of `[wind]`'s ("20:wind:sim:10:2.0").
The network faults (partition, isolate, degrade) share the table: agents.scenario.net_faults.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

from errors import ScenarioError
from transport.network_schema import NET_FAULT_ACTIONS

FAULT_ACTIONS = ("kill", "pause", "restart", "leave", "lie", "wind")
FAULT_KEYS = ("at_s", "action", "target", "duration_s", "mode", "gust_std_m_s")
# What a lying follower publishes (agents.follower.lie): its estimate offset, its link sums
# at the declared bound, a random walk on both, or its whole state frozen at the onset.
LIE_MODES = ("offset", "bound", "walk", "stale")
_TARGET_RE = re.compile(r"^(follower|target)-([0-9]+)$|^recorder$|^sim$")


@dataclass(frozen=True)
class FaultSpec:
    at_s: float
    action: str
    process: str  # the launcher's (0-based) process name: follower-0 is the file's follower-1
    duration_s: float | None = None
    mode: str | None = None  # lie: one of LIE_MODES
    gust_std_m_s: float | None = None  # wind: the gusts' strength in the window


def is_net_action(raw: Any) -> bool:
    """True when a `[[faults]]` table (or a --fault text) is a network fault."""
    if isinstance(raw, dict):
        return raw.get("action") in NET_FAULT_ACTIONS
    parts = raw.split(":") if isinstance(raw, str) else []
    return len(parts) >= 2 and parts[1] in NET_FAULT_ACTIONS


def parse_fault_table(raw: Any, where: str, n: int, m: int) -> FaultSpec:
    if not isinstance(raw, dict):
        raise ScenarioError(where, "must be a table")
    unknown = sorted(set(raw) - set(FAULT_KEYS))
    if unknown:
        raise ScenarioError(f"{where}.{unknown[0]}", f"unknown (known: {', '.join(FAULT_KEYS)})")
    at_s = _seconds(raw.get("at_s"), f"{where}.at_s", required=True)
    assert at_s is not None
    action = raw.get("action")
    if action not in FAULT_ACTIONS:
        raise ScenarioError(f"{where}.action", f"must be one of {FAULT_ACTIONS}, got {action!r}")
    process = _process(raw.get("target", "sim" if action == "wind" else None),
                       f"{where}.target", n, m)
    duration = _seconds(raw.get("duration_s"), f"{where}.duration_s", required=False)
    if action == "pause" and duration is None:
        raise ScenarioError(f"{where}.duration_s", "a pause needs its duration")
    if action == "kill" and duration is not None:
        raise ScenarioError(f"{where}.duration_s", "a kill has no duration (see --restart)")
    mode = _lie_mode(raw, where, action, process, duration)
    return FaultSpec(at_s, action, process, duration, mode,
                     _gust(raw, where, action, process, duration))


def _gust(raw: dict[str, Any], where: str, action: str, process: str,
          duration: float | None) -> float | None:
    """A wind window's gust strength, checked with its target and duration; None otherwise."""
    gust = raw.get("gust_std_m_s")
    if action != "wind":
        if gust is not None:
            raise ScenarioError(f"{where}.gust_std_m_s", f"is no setting of a {action}")
        return None
    if process != "sim":
        raise ScenarioError(f"{where}.target", "the wind blows in the simulator: sim")
    if not duration:
        raise ScenarioError(f"{where}.duration_s", "a wind window needs its duration (> 0)")
    if isinstance(gust, bool) or not isinstance(gust, int | float) or not math.isfinite(gust):
        raise ScenarioError(f"{where}.gust_std_m_s", f"must be a number of m/s, got {gust!r}")
    if gust < 0:
        raise ScenarioError(f"{where}.gust_std_m_s", f"must be >= 0, got {gust}")
    return float(gust)


def _lie_mode(raw: dict[str, Any], where: str, action: str, process: str,
              duration: float | None) -> str | None:
    """A lie's mode, checked with its target and duration; None for the other actions."""
    mode = raw.get("mode")
    if action != "lie":
        if mode is not None:
            raise ScenarioError(f"{where}.mode", f"is no setting of a {action}")
        return None
    if mode not in LIE_MODES:
        raise ScenarioError(f"{where}.mode", f"must be one of {LIE_MODES}, got {mode!r}")
    if not process.startswith("follower-"):
        raise ScenarioError(f"{where}.target", f"only a follower can lie, got {raw['target']!r}")
    if not duration:
        raise ScenarioError(f"{where}.duration_s", "a lie needs its duration (> 0)")
    return str(mode)


def parse_faults(raw: Any, n: int, m: int) -> tuple[FaultSpec, ...]:
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise ScenarioError("faults", "must be an array of tables: [[faults]]")
    faults = [parse_fault_table(t, f"faults[{k}]", n, m) for k, t in enumerate(raw)
              if not is_net_action(t)]
    return tuple(sorted(faults, key=lambda f: f.at_s))


def parse_fault_flag(text: str, n: int, m: int, where: str = "--fault") -> FaultSpec | None:
    """"AT_S:ACTION:TARGET[:DURATION_S[:MODE]]" (None for "none")."""
    if text == "none":
        return None
    parts = text.split(":")
    if len(parts) not in (3, 4, 5):
        raise ScenarioError(where, f"expected AT_S:ACTION:TARGET[:DURATION_S[:MODE]], "
                                   f"got {text!r}")
    table: dict[str, Any] = {"at_s": _number(parts[0], where), "action": parts[1],
                             "target": parts[2]}
    if len(parts) >= 4:
        table["duration_s"] = _number(parts[3], where)
    if len(parts) == 5 and parts[1] == "wind":
        table["gust_std_m_s"] = _number(parts[4], where)
    elif len(parts) == 5:
        table["mode"] = parts[4]
    return parse_fault_table(table, where, n, m)


def _number(text: str, where: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ScenarioError(where, f"{text!r} is not a number") from None


def _seconds(raw: Any, where: str, required: bool) -> float | None:
    if raw is None:
        if required:
            raise ScenarioError(where, "is required")
        return None
    if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw):
        raise ScenarioError(where, f"must be a number of seconds, got {raw!r}")
    if raw < 0:
        raise ScenarioError(where, f"must be >= 0, got {raw}")
    return float(raw)


def _process(raw: Any, where: str, n: int, m: int) -> str:
    if isinstance(raw, str) and re.fullmatch(r"router-\d+", raw):
        # the Zenoh router of host K (0-based, deploy.hosts.deployment); runs with --hosts
        return raw
    match = _TARGET_RE.match(raw) if isinstance(raw, str) else None
    if match is None:
        raise ScenarioError(where, f"must be follower-K, target-K, recorder or sim, got {raw!r}")
    if raw in ("recorder", "sim"):
        return str(raw)
    role, number = match.group(1), int(match.group(2))
    count = n if role == "follower" else m
    if not 1 <= number <= count:
        raise ScenarioError(where, f"{role}s are numbered 1..{count}, got {number}")
    return f"{role}-{number - 1}"
