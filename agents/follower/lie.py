"""A follower that lies on its own key: the `lie` fault (agents.scenario.faults).

An insider holding one follower's credentials can publish anything that key may carry:
valid, in bounds, from the key's owner.  The launcher makes the follower process itself
do so (deploy.launch.fault_injector), by a signal: `SIGRTMIN + k` starts lie mode `LIE_MODES[k]`,
`SIGRTMIN + len(LIE_MODES)` ends it.  The law keeps running honestly inside; only what
is published changes:
- offset: the estimate r moved by `OFFSET_M` (the issue-51 probe: 25 m off);
- bound:  every link sum at the declared bound (`FieldSpec.bound`, ~1e5 m), rates zero;
- walk:   the estimate and every link sum plus one random walk (`WALK_M_PER_SQRT_S`);
- stale:  the whole state frozen as it was at the onset, under fresh stamps.
What receivers make of it is agents.follower.plausible's concern.
"""

from __future__ import annotations

import math
import signal
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from agents.scenario.faults import LIE_MODES
from transport.law_fields import FieldSpec, LawFields, LawValue

if TYPE_CHECKING:
    from random import Random

OFFSET_M = 25.0 + 0j
WALK_M_PER_SQRT_S = 3.0  # ~16 m after 30 s: fast enough to matter, slow per message
BOUND_SHARE = 0.999  # of the declared bound: inside it, so every receiver's check passes


def begin_signal(mode: str) -> int:
    """The signal that starts lie mode `mode` in a follower process."""
    return int(signal.SIGRTMIN) + LIE_MODES.index(mode)


def end_signal() -> int:
    """The signal that ends any lie."""
    return int(signal.SIGRTMIN) + len(LIE_MODES)


@dataclass
class Published:
    """What a follower publishes of itself, before a lie touches it."""

    r: complex
    dr: complex
    pos: tuple[float, float]
    vel: tuple[float, float]
    fields: LawFields


class Liar:
    """The follower's lie, off until `begin`; `apply` turns a true state into a false one."""

    def __init__(self, specs: Mapping[str, FieldSpec], seed: int = 0) -> None:
        self.mode: str | None = None
        self._specs = specs
        self._seed = seed
        self._rng: Random | None = None  # made at the first walk: `random` is 0.2 MB of RSS
        self._walk = 0j
        self._last_s: float | None = None
        self._frozen: Published | None = None
        self.lies = 0  # states published false

    def begin(self, mode: str) -> None:
        self.mode, self._walk, self._last_s, self._frozen = mode, 0j, None, None

    def end(self) -> None:
        self.mode = None

    def install(self) -> None:
        """Handlers for the launcher's signals (main thread only: a process, not a test)."""
        for k, mode in enumerate(LIE_MODES):
            signal.signal(int(signal.SIGRTMIN) + k, lambda *_a, m=mode: self.begin(m))
        signal.signal(end_signal(), lambda *_a: self.end())

    def apply(self, now_s: float, true: Published) -> Published:
        mode = self.mode
        if mode is None:
            return true
        self.lies += 1
        if mode == "offset":
            return Published(true.r + OFFSET_M, true.dr, true.pos, true.vel, true.fields)
        if mode == "bound":
            return Published(true.r, true.dr, true.pos, true.vel, self._at_bound(true.fields))
        if mode == "walk":
            self._step_walk(now_s)
            return Published(true.r + self._walk, true.dr, true.pos, true.vel,
                             self._shifted(true.fields, self._walk))
        if self._frozen is None:
            self._frozen = true
        return self._frozen

    def _step_walk(self, now_s: float) -> None:
        dt = 0.0 if self._last_s is None else max(now_s - self._last_s, 0.0)
        self._last_s = now_s
        s = WALK_M_PER_SQRT_S * math.sqrt(dt)
        if self._rng is None:
            import random  # 0.2 MB of RSS in every follower, for a fault

            self._rng = random.Random(self._seed)
        self._walk += complex(self._rng.gauss(0.0, s), self._rng.gauss(0.0, s))

    def _at_bound(self, fields: LawFields) -> LawFields:
        """Every per_link field with a rate at the bound along x; its rate zero."""
        out: dict[str, LawValue] = dict(fields)
        for name, spec in self._specs.items():
            value = fields.get(name)
            if spec.kind != "per_link" or spec.rate is None or not isinstance(value, tuple):
                continue
            at = BOUND_SHARE * spec.bound
            out[name] = tuple((link[0], at, 0.0) for link in value)  # type: ignore[index]
            rate = fields.get(spec.rate)
            if isinstance(rate, tuple):
                out[spec.rate] = tuple((link[0], 0.0, 0.0) for link in rate)  # type: ignore[index]
        return out

    def _shifted(self, fields: LawFields, by: complex) -> LawFields:
        """Every per_link field with a rate moved by `by` (kept inside its bound)."""
        out: dict[str, LawValue] = dict(fields)
        for name, spec in self._specs.items():
            value = fields.get(name)
            if spec.kind != "per_link" or spec.rate is None or not isinstance(value, tuple):
                continue
            out[name] = tuple(_inside((link[0], link[1] + by.real, link[2] + by.imag),  # type: ignore[index]
                                      BOUND_SHARE * spec.bound) for link in value)
        return out


def _inside(link: tuple[int, float, float], bound: float) -> tuple[int, float, float]:
    mag = math.hypot(link[1], link[2])
    if mag <= bound:
        return link
    return (link[0], link[1] * bound / mag, link[2] * bound / mag)
