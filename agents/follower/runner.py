"""One follower's law and what the platform does around each of its steps.

`LawRunner` keeps the law's state (opaque here), the time of its last step (dt), its last
estimate (continuity across a change of members or a join: `Inputs.rebase_to`), and
calls the law guarded: a step that raises, returns a non-finite estimate or command, or
a field the law did not declare (or of the wrong kind, or not finite) is a failure:
counted, its traceback logged once (then at most every `LOG_EVERY_S`), and the vehicle
holds; the law's next good output is taken as if nothing happened.  Pure apart from the
log: the follower process (agents.follower.node) and the lock-step harness both run it.
"""

from __future__ import annotations

import logging
import math
import time
import traceback
from collections.abc import Mapping
from typing import Any

from agents.follower.journal import JournalWriter
from agents.law.interface import Inputs, Law, Output, Peer, Sample, Setup, reference
from agents.membership.follower_place import joined_estimate
from agents.shell.tick_cost import NoCost, TickCost
from transport.law_fields import FieldSpec, LawFields, LawValue

log = logging.getLogger("enclose.follower")
LOG_EVERY_S = 10.0
_new = tuple.__new__
NO_COST = NoCost()


class LawRunner:
    """Law `law` flown by follower `setup.index`."""

    def __init__(self, law: Law[Any], setup: Setup, start_s: float = 0.0) -> None:
        self.law = law
        self.declared: dict[str, FieldSpec] = law.declared()
        self._kinds = {name: spec.kind for name, spec in self.declared.items()}
        self.setup = setup
        self.state: Any = law.start(setup)
        self.last_r: Sample | None = None  # the estimate of its last good step
        self.last_step_s: float | None = None
        # The run's start on now_s's clock (`Inputs.t_s` is counted from it): lock-step's
        # 0; a follower's start word sets it (`window`), and so does the journal's replay.
        self.start_s = start_s
        self.rebase = False  # continue from last_r (a change of members, a join)
        self.failures = 0
        self._next_log_s = -math.inf
        # What the law is handed and gives, for `enclose replay` (agents.follower.journal)
        self.journal: JournalWriter | None = None

    def _journal(self, write: Any, *args: Any) -> None:
        """A journal write; a journal that cannot be written is dropped, the flight goes on."""
        if self.journal is None:
            return
        try:
            write(*args)
        except (OSError, ValueError, TypeError) as exc:
            log.error("input journal stopped: %s", exc)
            self.journal = None

    def step(self, now_s: float, command: bool, own: Sample, targets: Mapping[int, Sample],
             peers: Mapping[int, Peer], cost: TickCost | NoCost = NO_COST,
             ) -> tuple[Output, LawFields] | None:
        """`_step`, journaled; `cost` marks the two (agents.shell.tick_cost)."""
        result = self._step(now_s, command, own, targets, peers)
        if self.journal is not None:
            cost.mark("law")
            self._journal(self.journal.step, now_s, command, own, targets, peers, result)
            cost.mark("journal")
        return result

    def _step(self, now_s: float, command: bool, own: Sample, targets: Mapping[int, Sample],
              peers: Mapping[int, Peer]) -> tuple[Output, LawFields] | None:
        """One step of the law: its output and its fields as published; None if it failed
        (counted and logged: the caller holds the vehicle and publishes nothing).  The
        output's command is the law's on a control tick (0 if it was not finite), and
        meaningless otherwise."""
        setup, last = self.setup, self.last_step_s
        dt = 0.0 if last is None else min(max(now_s - last, 0.0), setup.max_gap_s)
        rebase_to = None
        if self.rebase and self.last_r is not None:
            rebase_to = self.last_r.held(now_s, setup.hold_s)
        inputs = _new(Inputs, (now_s, dt, command, setup, own, targets, peers, rebase_to,
                               now_s - self.start_s))
        try:
            state, out = self.law.step(self.state, inputs)
            wire = self._wire(out)
            u = out.u_m_s
        except Exception:  # the law's own bug: the vehicle holds, the follower goes on
            self._failed(traceback.format_exc())
            return None
        self.state, self.last_step_s = state, now_s
        self.last_r = _new(Sample, (out.r_m, out.dr_m_s, now_s))
        if self.rebase:  # a target newly ours not heard yet: the law's reference lacks it,
            # so the estimate stays carried until it is
            self.rebase = not all(j in targets for j in setup.observed)
        if command and not (type(u) is complex and u.real - u.real + u.imag - u.imag == 0.0):
            # its estimate and fields are good: they are published, the vehicle holds
            self._failed(f"non-finite command {u!r}")
            return _new(Output, (0j, out.r_m, out.dr_m_s, out.fields)), wire
        return out, wire

    def _wire(self, out: Output) -> LawFields:
        """`out`'s fields as FollowerState.law carries them; ValueError if its estimate is
        not a finite complex, or a field is undeclared, not of its declared kind or not
        finite.  Its bound is every receiver's check (transport.law_fields): beyond it,
        neighbours drop the message and count it."""
        r, dr, fields = out.r_m, out.dr_m_s, out.fields
        if not (type(r) is complex and type(dr) is complex
                and r.real - r.real + r.imag - r.imag + dr.real - dr.real + dr.imag
                - dr.imag == 0.0):
            raise ValueError(f"the estimate must be finite complex numbers: r = {r!r}, "
                             f"dr = {dr!r}")
        kinds, nbrs = self._kinds, self.setup.neighbours
        wire: dict[str, LawValue] = {}
        total = 0j  # finite iff every number is (short of an overflow: far past any bound)
        for name, value in fields.items():
            kind = kinds.get(name)
            if kind == "per_link" and len(value) == len(nbrs):
                links = []  # a plain loop: a comprehension or a strict zip costs more here
                for j, v in zip(nbrs, value, strict=False):  # lengths compared above
                    links.append((j, v.real, v.imag))
                    total += v
                wire[name] = tuple(links)
            elif kind == "vec2" and type(value) is complex:
                wire[name] = (value.real, value.imag)
                total += value
            elif kind == "scalar" and type(value) in (float, int):
                wire[name] = float(value)
                total += value
            else:
                raise ValueError(f"field {name!r}: {'not declared' if kind is None else kind} "
                                 f"is not {value!r}")
        if total.real - total.real + total.imag - total.imag != 0.0:
            raise ValueError(f"a field is not finite: {fields!r}")
        return wire

    def failed(self, detail: str) -> None:
        """A failure of the law's found past its step (its fields did not encode)."""
        self._failed(detail)

    def _failed(self, detail: str) -> None:
        self.failures += 1
        now = time.monotonic()
        if self.failures == 1 or now >= self._next_log_s:
            self._next_log_s = now + LOG_EVERY_S
            log.error("law %r failed (%d so far), the vehicle holds: %s",
                      self.law.name, self.failures, detail)

    def regroup(self, new: Setup) -> None:
        """The member set changed: the law's state carried (its `regroup`; starting afresh
        if that fails), and the estimate continued from the last one."""
        try:
            self.state = self.law.regroup(self.state, self.setup, new)
        except Exception:
            self._failed(traceback.format_exc())
            try:
                self.state = self.law.start(new)
            except Exception:
                self._failed(traceback.format_exc())
        self.setup = new
        self.rebase = True
        if self.journal is not None:
            self._journal(self.journal.regroup, new.members)

    def window(self, start_s: float, stop_s: float) -> None:
        """The experiment's start and stop (the run's control words): the origin of the
        law's `t_s`, journaled (a replay derives `t_s` from it and the steps' `now_s`)."""
        self.start_s = start_s
        if self.journal is not None:
            self._journal(self.journal.window, start_s, stop_s)

    def continue_estimate(self) -> bool:
        """A neighbour heard again after a silence (a healed cut) may publish link sums that
        moved meanwhile: the next step continues the estimate from the last one, as across
        a change of members.  Journaled: the replay must do the same at the same step.
        False before the first step (nothing to continue from)."""
        if self.last_r is None:
            return False
        self.rebase = True
        if self.journal is not None:
            self._journal(self.journal.rebase)
        return True

    def join(self, peers: Mapping[int, Peer], now_s: float) -> None:
        """Joining a running swarm: continue from the neighbours' mean estimate."""
        if self.last_r is not None:
            return
        if self.journal is not None:
            self._journal(self.journal.join, peers, now_s)
        joined = joined_estimate(peers, self.setup, now_s)
        if joined is not None:
            self.last_r, self.rebase = joined, True

    def standing_estimate(self, targets: Mapping[int, Sample], now_s: float) -> complex:
        """What a follower publishes as its estimate while its law is not running: its
        last one held, or, before the first, its weighted target position."""
        if self.last_r is None:
            return reference(self.setup, targets, now_s)[0]
        return self.last_r.held(now_s, self.setup.hold_s)
