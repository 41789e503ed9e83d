"""Every Zenoh key expression of the swarm, built in this one module.

All keys live under `enclose/<swarm>/`, so several swarms can share a router or
a machine without hearing each other.  Followers, sensors and status keys carry
a 0-based index.  `key_matches` implements the Zenoh wildcard rules the
in-memory bus needs (`*` is exactly one non-empty chunk, `**` any number of
chunks, including none).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache

from errors import ConfigError

ROOT = "enclose"
# Zenoh reserves `*`, `$`, `#`, `?` and `/` separates chunks; a strict whitelist is simpler.
_NAME_RE = re.compile(r"[A-Za-z0-9_.-]{1,64}")  # fullmatch: "$" would pass "a\n"
_WILDCARDS = ("*", "$", "#", "?")


def validate_name(name: str, field: str = "swarm") -> str:
    """Return `name` if it is a valid single key chunk, else raise ConfigError."""
    if not isinstance(name, str) or not _NAME_RE.fullmatch(name):
        raise ConfigError(field, f"{name!r} must be 1-64 characters of [A-Za-z0-9_.-]")
    return name


def _index(i: int, field: str) -> int:
    if isinstance(i, bool) or not isinstance(i, int) or i < 0:
        raise ConfigError(field, f"{i!r} must be a non-negative int")
    return i


def validate_concrete(key: str) -> str:
    """A key one can publish on: non-empty chunks, no wildcard or reserved character."""
    chunks = key.split("/")
    if not key or any(not c for c in chunks) or any(w in key for w in _WILDCARDS):
        raise ConfigError("key", f"{key!r} is not a concrete key expression")
    return key


@dataclass(frozen=True)
class SwarmKeys:
    """Key builder for one swarm; every key of the system comes from here."""

    swarm: str

    def __post_init__(self) -> None:
        validate_name(self.swarm, "swarm")

    @property
    def prefix(self) -> str:
        return f"{ROOT}/{self.swarm}"

    def follower_state(self, i: int) -> str:
        return f"{self.prefix}/follower/{_index(i, 'follower')}/state"

    def follower_estimate(self, i: int) -> str:
        """Follower i's state at its estimator's rate, between the states of its control
        ticks (issue 15): same message, for its neighbours only (not recorded)."""
        return f"{self.prefix}/follower/{_index(i, 'follower')}/est"

    def sensor_targets(self, i: int) -> str:
        """Where the simulator publishes the targets follower `i` observes."""
        return f"{self.prefix}/sensor/{_index(i, 'follower')}/targets"

    def truth(self) -> str:
        return f"{self.prefix}/truth"

    def control(self) -> str:
        """The launcher's start/stop word to every process of the swarm."""
        return f"{self.prefix}/control"

    def status(self, role: str, i: int) -> str:
        return f"{self.prefix}/status/{validate_name(role, 'role')}/{_index(i, 'index')}"

    def alive(self, role: str, i: int) -> str:
        """Liveliness token key of process (`role`, `i`)."""
        return f"{self.prefix}/alive/{validate_name(role, 'role')}/{_index(i, 'index')}"

    # Wildcards, for recorders, launchers and tests.
    def clock(self, role: str, i: int) -> str:
        """Clock probes of process (role, i) (transport.clock_sync)."""
        return f"{self.prefix}/clock/{validate_name(role, 'role')}/{_index(i, 'index')}"

    def role_clocks(self, role: str) -> str:
        """Clock probes of every process of `role` (the hosts' routers probe each other)."""
        return f"{self.prefix}/clock/{validate_name(role, 'role')}/*"

    def all_follower_states(self) -> str:
        return f"{self.prefix}/follower/*/state"

    def all_sensor_targets(self) -> str:
        return f"{self.prefix}/sensor/*/targets"

    def all_status(self) -> str:
        return f"{self.prefix}/status/**"

    def all_alive(self) -> str:
        return f"{self.prefix}/alive/**"

    def alive_of(self, role: str) -> str:
        """Liveliness tokens of every process of `role` (e.g. the followers)."""
        return f"{self.prefix}/alive/{validate_name(role, 'role')}/*"

    def status_of(self, role: str) -> str:
        return f"{self.prefix}/status/{validate_name(role, 'role')}/*"

    def everything(self) -> str:
        return f"{self.prefix}/**"

    def recorded(self, sensor: bool = True) -> tuple[str, ...]:
        """What a recorder subscribes to: everything but the estimator-rate states, and but
        the target observations when `sensor` is false."""
        observed = (self.all_sensor_targets(),) if sensor else ()
        return (self.all_follower_states(), *observed, self.truth(), self.control(),
                self.all_status(), self.all_alive())


@dataclass(frozen=True)
class KeyInfo:
    """What a concrete key names: `kind` is follower|sensor|truth|control|status|alive."""

    swarm: str
    kind: str
    role: str | None = None
    index: int | None = None


# One spelling per index: ASCII digits, no sign, no leading zero, below 10^9.  Keys come
# from the network, and `str.isdigit` takes digits `int` refuses ("²") or reads ("٣").
_INDEX_RE = re.compile(r"0|[1-9][0-9]{0,8}")
_SUFFIXES = {"follower": ("state", "est"), "sensor": ("targets",)}


# Every received message's key is parsed (its sender, its index): a process hears a few
# dozen keys, so a cache answers; bounded, since keys come from the network.
@lru_cache(maxsize=1024)
def parse_key(key: str) -> KeyInfo | None:
    """Decompose a concrete swarm key (e.g. to find the sender of a link); None if foreign
    or malformed.  Total: never raises, whatever the string."""
    if not isinstance(key, str):
        return None
    parts = key.split("/")
    if len(parts) < 3 or parts[0] != ROOT or not _NAME_RE.fullmatch(parts[1]):
        return None
    swarm, kind, rest = parts[1], parts[2], parts[3:]
    if kind in ("truth", "control") and not rest:
        return KeyInfo(swarm, kind)
    if len(rest) != 2:
        return None
    if kind in _SUFFIXES and _INDEX_RE.fullmatch(rest[0]) and rest[1] in _SUFFIXES[kind]:
        return KeyInfo(swarm, kind, "follower", int(rest[0]))
    if kind in ("status", "alive", "clock") and _NAME_RE.fullmatch(rest[0]) \
            and _INDEX_RE.fullmatch(rest[1]):
        return KeyInfo(swarm, kind, rest[0], int(rest[1]))
    return None


def key_matches(key_expr: str, key: str) -> bool:
    """True if the concrete `key` is matched by `key_expr` (Zenoh `*` / `**` semantics)."""
    return _match(key_expr.split("/"), key.split("/"))


def _match(pattern: list[str], chunks: list[str]) -> bool:
    if not pattern:
        return not chunks
    head, tail = pattern[0], pattern[1:]
    if head == "**":
        return any(_match(tail, chunks[k:]) for k in range(len(chunks) + 1))
    if not chunks:
        return False
    if head == "*" or head == chunks[0]:
        return _match(tail, chunks[1:])
    if "*" in head:
        # A chunk such as `st*` : `*` matches any run of characters within the chunk.
        regex = "^" + ".*".join(re.escape(p) for p in head.split("*")) + "$"
        return re.match(regex, chunks[0]) is not None and _match(tail, chunks[1:])
    return False
