"""Messages checked, not trusted: plausibility of a decoded message on its key, at a time.

Pure functions (no clock: the caller passes `now_s`, the receive stamp).  Access control
already keeps other processes off a key (transport.access); these checks catch what a
process holding the right key could still send wrong -- or what arrives with `--insecure`:
- key (always, `key_reason`): only one message type belongs on each kind of key (a
  FollowerState on a follower key, a ProcessStatus on a status key, ...), and the index it
  carries (a state's follower, an observation's observer, a status's role and index) is
  the key's: a process holding its own key cannot pass for another through the payload;
- sender: the header's sender id must be the process that owns the key
  (`follower-<i>` on follower i's state, `sim-0` on sensor and truth, `launcher-0` on
  control, `<role>-<i>` on status key <role>/<i>);
- time: a stamp more than `future_s` ahead of the receiver's clock, or more than
  `max_age_s` behind it, is refused -- a forged future stamp must not win "newest".  The
  same rule holds the stamps inside a message (a state's vehicle stamp, an observation's
  observed stamp), and an observation cannot be observed after it was sent;
- values: every number finite, positions within `max_pos_m` of the origin, speeds below
  `max_speed_m_s` (no vehicle flies faster: a value beyond is a forgery or a fault); a
  law's own fields are held to the kinds and bounds it declared by a receiver that knows
  the law (transport.law_fields, in the decoder), and are finite once decoded.
A refusal is a short reason string, counted by the decoder as `drop_rejected_<reason>`.

Every message a process accepts passes here, so the common case is cheap: the numbers of
a message are summed (finite iff every one is finite, unless the sum overflows) and the
generic, exact test (`_finite`, `_follower_reason_exact`) runs only when the sum is not
a finite float.  The two agree on every message of ints, floats and bools -- what the
codec makes (tests/unit/test_checks_fast.py pins them).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import lru_cache

from transport.key_exprs import parse_key
from transport.messages import (
    ClockProbe,
    FollowerState,
    Message,
    ProcessStatus,
    RunControl,
    TargetObservation,
    TruthSnapshot,
)


@dataclass(frozen=True)
class Limits:
    future_s: float = 0.5  # clocks of one machine agree; NTP'd hosts within a few ms
    max_age_s: float = 60.0
    max_pos_m: float = 1e5
    max_speed_m_s: float = 1e3


DEFAULT_LIMITS = Limits()
# The recorder refuses future stamps but not old ones: it also records replays of
# synthetic runs, whose stamps are from another day.
RECORDER_LIMITS = Limits(max_age_s=math.inf)


def _finite(values: Iterable[float]) -> bool:
    return all(isinstance(v, int | float) and math.isfinite(v) for v in values)


def _bounded(vectors: Iterable[tuple[float, ...]], bound: float) -> bool:
    return all(math.hypot(*v) <= bound for v in vectors)


@dataclass(frozen=True)
class KeyRule:
    """What may arrive on one swarm key."""

    owner: str  # the sender id of the one process that publishes there
    kind: type | None  # the one message type that belongs there (None: none does)
    index: int | None = None  # the index its message carries
    role: str | None = None  # a status's role
    about: str = ""  # the process the key is about: its owner, or a sensor key's follower

    def subject(self) -> str:
        return self.about or self.owner


_KINDS: dict[str, type] = {"follower": FollowerState, "sensor": TargetObservation,
                           "truth": TruthSnapshot, "control": RunControl,
                           "status": ProcessStatus, "clock": ClockProbe}


@lru_cache(maxsize=1024)  # keys come from the network: bounded
def key_rule(key: str) -> KeyRule | None:
    """The rule of a swarm key; None for a foreign key (any sender, any type)."""
    info = parse_key(key)
    if info is None:
        return None
    kind = _KINDS.get(info.kind)  # a liveliness key carries no message
    if info.kind == "follower":
        return KeyRule(f"follower-{info.index}", kind, info.index)
    if info.kind == "sensor":
        return KeyRule("sim-0", kind, info.index, about=f"follower-{info.index}")
    if info.kind == "truth":
        return KeyRule("sim-0", kind)
    if info.kind == "control":
        return KeyRule("launcher-0", kind)
    if info.kind == "status":
        return KeyRule(f"{info.role}-{info.index}", kind, info.index, info.role)
    return KeyRule(f"{info.role}-{info.index}", kind)


def key_reason(msg: Message, key: str) -> str | None:
    """None if `msg` belongs on `key` (type, and the index and role it carries); else
    `wrong_key` (a type that never travels there) or `key_mismatch` (another's index)."""
    rule = key_rule(key)
    if rule is None:
        return None
    if type(msg) is not rule.kind:
        return "wrong_key"
    if isinstance(msg, TargetObservation):
        carried = msg.observer_index
    elif isinstance(msg, FollowerState | ProcessStatus):
        carried = msg.index
    else:  # truth, control, clock: no index in the message
        return None
    if carried != rule.index or (isinstance(msg, ProcessStatus) and msg.role != rule.role):
        return "key_mismatch"
    return None


def _time_reason(stamp_s: float, now_s: float, lim: Limits) -> str | None:
    if not math.isfinite(stamp_s):
        return "nonfinite"
    if stamp_s > now_s + lim.future_s:
        return "future_stamp"
    if stamp_s < now_s - lim.max_age_s:
        return "old_stamp"
    return None


def check(msg: Message, key: str, now_s: float, lim: Limits = DEFAULT_LIMITS) -> str | None:
    """None if `msg`, received on `key` at `now_s`, is plausible; else why not."""
    rule = key_rule(key)
    if rule is not None and msg.header.sender_id != rule.owner:
        return "sender"
    # The message types are disjoint: the most frequent ones are tested first.
    if isinstance(msg, FollowerState):
        return _time_reason(msg.header.stamp_s, now_s, lim) or _follower_reason(msg, now_s, lim)
    if isinstance(msg, TargetObservation):
        return _time_reason(msg.header.stamp_s, now_s, lim) \
            or _observation_reason(msg, now_s, lim)
    if isinstance(msg, ProcessStatus):
        return None  # counters for people, tied to their sender by the key and sender rules
    if isinstance(msg, RunControl):
        ok = _finite((msg.start_stamp_s, msg.duration_s)) and msg.duration_s >= 0
        return _time_reason(msg.header.stamp_s, now_s, lim) or (None if ok else "impossible")
    reason = _time_reason(msg.header.stamp_s, now_s, lim)
    if reason is not None:
        return reason
    if isinstance(msg, TruthSnapshot):
        vecs = [*msg.follower_pos_m, *msg.follower_vel_m_s, *msg.target_pos_m, *msg.target_vel_m_s]
        fine = _finite_sum(lambda: sum(map(sum, vecs), 0.0))
        return None if fine or all(_finite(v) for v in vecs) else "nonfinite"
    return None


def _finite_sum(total: Callable[[], object]) -> bool:
    """Is the sum of some numbers that `total` adds up a finite float?  Then every one of
    them was finite.  False also when they are not numbers (the exact test says more)."""
    try:
        s = total()
    except (TypeError, ValueError, OverflowError):
        return False
    return type(s) is float and s - s == 0.0


def _observation_reason(msg: TargetObservation, now_s: float, lim: Limits) -> str | None:
    """Values as a state's; the observed stamp as the header's (the follower keeps a
    target's newest observation: one stamped in the future would hold it there), and
    not after the header's (a sensor cannot send what it has not yet seen)."""
    pos, seen_s = msg.pos_m, msg.observed_stamp_s
    if not _finite_sum(lambda: sum(pos, seen_s)) and not _finite((*pos, seen_s)):
        return "nonfinite"
    reason = _time_reason(seen_s, now_s, lim)
    if reason is not None:
        return reason
    if seen_s > msg.header.stamp_s:
        return "future_stamp"
    return None if math.hypot(*pos) <= lim.max_pos_m else "impossible"


def _follower_reason(msg: FollowerState, now_s: float, lim: Limits) -> str | None:
    """As _follower_reason_exact, in straight-line code when every number is finite.  The
    law's fields are not looked at: the codec decodes only finite ones, and a receiver
    that knows the law holds them to its declaration (transport.law_fields.reason, in
    transport.decoder)."""
    try:
        r0, r1 = msg.r_m
        x0, x1 = msg.pos_m
        d0, d1 = msg.dr_m_s
        v0, v1 = msg.vel_m_s
        u0, u1 = msg.u_m_s
        vst = msg.vehicle_stamp_s
        s = r0 + r1 + x0 + x1 + d0 + d1 + v0 + v1 + u0 + u1 + vst
    except (TypeError, ValueError, OverflowError):  # not numbers, or not pairs
        return _follower_reason_exact(msg, now_s, lim)
    if not (type(s) is float and s - s == 0.0):
        return _follower_reason_exact(msg, now_s, lim)
    if vst > now_s + lim.future_s:
        return "future_stamp"
    hypot, pos_max, speed_max = math.hypot, lim.max_pos_m, lim.max_speed_m_s
    if not (hypot(r0, r1) <= pos_max and hypot(x0, x1) <= pos_max
            and hypot(d0, d1) <= speed_max and hypot(v0, v1) <= speed_max
            and hypot(u0, u1) <= speed_max):
        return "impossible"
    return None


def _follower_reason_exact(msg: FollowerState, now_s: float, lim: Limits) -> str | None:
    positions = [msg.r_m, msg.pos_m]
    speeds = [msg.dr_m_s, msg.vel_m_s, msg.u_m_s]
    numbers = [*(x for v in positions + speeds for x in v), msg.vehicle_stamp_s]
    if not _finite(numbers):
        return "nonfinite"
    if msg.vehicle_stamp_s > now_s + lim.future_s:
        return "future_stamp"
    if not (_bounded(positions, lim.max_pos_m) and _bounded(speeds, lim.max_speed_m_s)):
        return "impossible"
    return None


def newer(stamp_s: float, known_stamp_s: float, now_s: float) -> bool:
    """Replace a neighbour's kept state by one stamped `stamp_s`?  Newer wins -- and a kept
    state stamped in our future (within the tolerance) is replaced by the next one, so one
    message can never freeze the view, however it is stamped."""
    return stamp_s > known_stamp_s or known_stamp_s > now_s
