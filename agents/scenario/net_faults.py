"""The network faults of a scenario's `[[faults]]`: partition, isolate, degrade, validated once.

    [[faults]]
    at_s = 40.0
    action = "partition"        # partition | isolate | degrade
    duration_s = 15.0           # required: the window is [at_s, at_s + duration_s)
    groups = [[1, 2], [3, 4]]   # partition: followers (1-based) that hear only their group
    # target = "follower-2"     # isolate: the follower cut off from every other
    # links = [[1, 2], [2, 1]]  # degrade: (from, to) links; absent: every follower link
    # delay_ms, jitter_ms, loss, loss_model, burst_len, duplicate, reorder: degrade's
    #   impairment, as in [network] (a loss of 1 is a cut: use a partition)

Followers named in no group of a partition form one more group.  The cut is made where
messages are received (transport.impairment, transport.net_timeline); the simulator's
sensor link is never cut.  On the command line (`--fault`, and `fault` in a sweep):
"AT_S:partition:1,2|3,4:DURATION_S", "AT_S:isolate:follower-K:DURATION_S",
"AT_S:degrade:LINKS:DURATION_S:KEY=VALUE,..." with LINKS "all" or "1>2,2>1".
"""

from __future__ import annotations

import math
from typing import Any

from agents.scenario.faults import is_net_action, parse_fault_flag
from agents.scenario.network import IMPAIRMENT_KEYS, impairment
from errors import ScenarioError
from transport.network_schema import LinkImpairment, NetFault

NET_FAULT_KEYS = ("at_s", "action", "duration_s", "groups", "target", "links", *IMPAIRMENT_KEYS)


def check_fault_flag(text: str, n: int, m: int, where: str) -> None:
    """A --fault text of either kind (a process fault, a network fault), checked."""
    if is_net_action(text):
        parse_net_fault_flag(text, n, where)
    else:
        parse_fault_flag(text, n, m, where)


def parse_net_fault_table(raw: dict[str, Any], where: str, n: int) -> NetFault:
    unknown = sorted(set(raw) - set(NET_FAULT_KEYS))
    if unknown:
        raise ScenarioError(f"{where}.{unknown[0]}",
                            f"unknown (known: {', '.join(NET_FAULT_KEYS)})")
    action = str(raw["action"])
    at_s = _seconds(raw.get("at_s"), f"{where}.at_s")
    duration_s = _seconds(raw.get("duration_s"), f"{where}.duration_s")
    groups: tuple[frozenset[int], ...] = ()
    links: tuple[tuple[int, int], ...] = ()
    spec = LinkImpairment()
    if action == "partition":
        groups = _groups(raw.get("groups"), f"{where}.groups", n)
    elif action == "isolate":
        groups = (frozenset({_follower(raw.get("target"), f"{where}.target", n)}),)
    else:
        links = _links(raw.get("links", []), f"{where}.links", n)
        spec = impairment(raw, where, LinkImpairment())
    misplaced = [k for k in ("groups", "target", "links", *IMPAIRMENT_KEYS)
                 if k in raw and not _belongs(k, action)]
    if misplaced:
        raise ScenarioError(f"{where}.{misplaced[0]}", f"is no setting of a {action}")
    return NetFault(action, at_s, duration_s, groups, links, spec)


def parse_net_faults(raw: Any, n: int, run_s: float) -> tuple[NetFault, ...]:
    """The network faults among `[[faults]]` (the others: agents.scenario.faults)."""
    if not isinstance(raw, list):
        return ()
    faults = [parse_net_fault_table(t, f"faults[{k}]", n)
              for k, t in enumerate(raw) if is_net_action(t)]
    for k, fault in enumerate(faults):
        check_window(fault, f"faults[{k}].duration_s", run_s)
    return tuple(sorted(faults, key=lambda f: f.at_s))


def check_window(fault: NetFault, where: str, run_s: float) -> None:
    if fault.end_s > run_s:
        raise ScenarioError(where, f"the window ends at {fault.end_s:g} s, past the run's "
                                   f"end ({run_s:g} s)")


def parse_net_fault_flag(text: str, n: int, where: str = "--fault") -> NetFault:
    """A network fault given as text (module docstring)."""
    parts = text.split(":")
    if len(parts) not in (4, 5):
        raise ScenarioError(where, f"expected AT_S:ACTION:WHO:DURATION_S[:KEY=VALUE,...], "
                                   f"got {text!r}")
    table: dict[str, Any] = {"at_s": _number(parts[0], where), "action": parts[1],
                             "duration_s": _number(parts[3], where)}
    who = parts[2]
    if parts[1] == "partition":
        table["groups"] = [[_int(x, where) for x in g.split(",")] for g in who.split("|")]
    elif parts[1] == "isolate":
        table["target"] = who
    elif who != "all":
        table["links"] = [[_int(x, where) for x in link.split(">")] for link in who.split(",")]
    for item in parts[4].split(",") if len(parts) == 5 else []:
        key, _, value = item.partition("=")
        table[key] = value if key == "loss_model" else _number(value, where)
    return parse_net_fault_table(table, where, n)


def _belongs(key: str, action: str) -> bool:
    if key == "groups":
        return action == "partition"
    if key == "target":
        return action == "isolate"
    return action == "degrade"


def _groups(raw: Any, where: str, n: int) -> tuple[frozenset[int], ...]:
    if not isinstance(raw, list) or len(raw) < 1 or not all(isinstance(g, list) for g in raw):
        raise ScenarioError(where, "must be an array of follower-number arrays, e.g. [[1, 2], [3]]")
    seen: set[int] = set()
    groups = []
    for k, g in enumerate(raw):
        members = frozenset(_number_of(v, f"{where}[{k}]", n) for v in g)
        if not members:
            raise ScenarioError(f"{where}[{k}]", "is empty")
        if members & seen:
            raise ScenarioError(f"{where}[{k}]", f"overlaps another group: follower "
                                                 f"{min(members & seen) + 1}")
        seen |= members
        groups.append(members)
    if len(groups) < 2 and seen == set(range(n)):
        raise ScenarioError(where, "one group of every follower cuts nothing")
    return tuple(groups)


def _links(raw: Any, where: str, n: int) -> tuple[tuple[int, int], ...]:
    if not isinstance(raw, list):
        raise ScenarioError(where, "must be an array of [from, to] pairs")
    links = []
    for k, link in enumerate(raw):
        if not isinstance(link, list) or len(link) != 2:
            raise ScenarioError(f"{where}[{k}]", f"must be a [from, to] pair, got {link!r}")
        links.append((_number_of(link[0], f"{where}[{k}]", n),
                      _number_of(link[1], f"{where}[{k}]", n)))
    return tuple(links)


def _follower(raw: Any, where: str, n: int) -> int:
    text = raw if isinstance(raw, str) else ""
    if not text.startswith("follower-"):
        raise ScenarioError(where, f"must be follower-K, got {raw!r}")
    return _number_of(_int(text.removeprefix("follower-"), where), where, n)


def _number_of(raw: Any, where: str, n: int) -> int:
    """A 1-based follower number, as the 0-based index."""
    if isinstance(raw, bool) or not isinstance(raw, int) or not 1 <= raw <= n:
        raise ScenarioError(where, f"followers are numbered 1..{n}, got {raw!r}")
    return raw - 1


def _seconds(raw: Any, where: str) -> float:
    if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw):
        raise ScenarioError(where, f"must be a number of seconds, got {raw!r}")
    if raw < 0:
        raise ScenarioError(where, f"must be >= 0, got {raw}")
    return float(raw)


def _number(text: str, where: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ScenarioError(where, f"{text!r} is not a number") from None


def _int(text: str, where: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ScenarioError(where, f"{text!r} is not a follower number") from None
