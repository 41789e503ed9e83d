"""The newest of every input a follower's law reads: targets and neighbours' messages.

Messages arrive decoded, checked and on this follower's clock (transport.decoder with
the law's declared fields: transport.law_fields), and a neighbour's state must be
plausible (agents.follower.plausible): an implausible one is dropped and counted, as if
never sent.  Here they become what a law reads
(agents.law.interface): a target's position with the platform's velocity estimate, a
peer's estimate, vehicle state and declared fields as `Sample`s at their stamps (a
per_link field: only the entry addressed to this follower).  Only the newest message of
a peer is kept; ages and staleness are read against `Setup.stale_s` at the step.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from agents.follower.plausible import GateLimits, Plausibility
from agents.law.interface import Peer, Sample, Setup
from agents.law.target_velocity import finite_difference_velocity, lag_free_velocity
from agents.membership.follower_place import (
    HOLD_AFTER_S,
    MAX_GAP_S,
    TARGET_ACCEL_TAU_S,
    TARGET_VEL_TAU_S,
)
from transport.law_fields import FieldSpec
from transport.message_checks import newer
from transport.messages import FollowerState

# A NamedTuple built without its Python-level __new__: half the cost, same object.
_new = tuple.__new__
_SCALAR, _VEC2, _PER_LINK = 0, 1, 2
_KIND_CODE = {"scalar": _SCALAR, "vec2": _VEC2, "per_link": _PER_LINK}


class Latest:
    """The newest target observations and peer messages of follower `index`, for a law
    that declared `specs`."""

    def __init__(self, index: int, specs: Mapping[str, FieldSpec],
                 limits: GateLimits | None = None) -> None:
        self.index = index
        odd = tuple(name for name, s in specs.items() if s.odd)
        self.gate = Plausibility(index, limits or GateLimits(), odd, HOLD_AFTER_S,
                                 MAX_GAP_S)
        self.targets: dict[int, Sample] = {}
        # Per target heard twice or more, its velocity filter's state: the low-passed
        # velocity and acceleration of lag_free_velocity.
        self.filters: dict[int, tuple[complex, complex]] = {}
        self.peers: dict[int, Peer] = {}
        self._kinds = {name: _KIND_CODE[s.kind] for name, s in specs.items()}
        # A field with a rate is kept as a Sample of both (agents.law.interface.Peer).
        self._rated = tuple((name, s.rate, 0j if s.kind != "scalar" else 0.0)
                            for name, s in specs.items() if s.rate is not None)

    def observe(self, setup: Setup, target: int, pos_m: complex, stamp_s: float) -> None:
        """Fold one observation in: position, and velocity by finite difference, low-passed
        and corrected for the lag that costs (lag_free_velocity)."""
        if target not in setup.observed:
            return
        prev = self.targets.get(target)
        if prev is None:
            self.targets[target] = _new(Sample, (pos_m, 0j, stamp_s))
            return
        value, _, prev_s = prev
        if stamp_s <= prev_s:
            return  # duplicate or reordered: the newer sample stands
        filt = self.filters.get(target)
        if filt is None:  # the second sample: the raw difference
            vel = finite_difference_velocity(value, prev_s, pos_m, stamp_s, 0j)
            self.filters[target] = (vel, 0j)
        else:
            vel, smooth, accel = lag_free_velocity(
                value, prev_s, pos_m, stamp_s, filt[0], filt[1], TARGET_VEL_TAU_S,
                TARGET_ACCEL_TAU_S)
            self.filters[target] = (smooth, accel)
        self.targets[target] = _new(Sample, (pos_m, vel, stamp_s))

    def receive(self, msg: FollowerState, now_s: float) -> None:
        """Keep `msg` if it is the peer's newest (transport.message_checks.newer) and plausible."""
        known = self.peers.get(msg.index)
        if known is None or newer(msg.header.stamp_s, known.r.stamp_s, now_s):
            peer = self.peer(msg)
            if self.gate.check(msg.index, peer, now_s) is None:
                self.peers[msg.index] = peer

    def peer(self, msg: FollowerState) -> Peer:
        """What this follower keeps of a peer's message."""
        stamp = msg.header.stamp_s
        fields: dict[str, object] = {}
        if msg.law:
            kinds, me = self._kinds, self.index
            value: Any
            for name, value in msg.law.items():
                kind = kinds.get(name)
                if kind == _PER_LINK:
                    for link in value:
                        if link[0] == me:
                            fields[name] = complex(link[1], link[2])
                            break
                elif kind == _VEC2:
                    fields[name] = complex(value[0], value[1])
                elif kind == _SCALAR:
                    fields[name] = value
            for name, rate, zero in self._rated:  # a rated field: a Sample of both
                held = fields.get(name)
                if held is not None:
                    fields[name] = _new(Sample, (held, fields.get(rate, zero), stamp))
        r, dr, pos, vel = msg.r_m, msg.dr_m_s, msg.pos_m, msg.vel_m_s
        return _new(Peer, (_new(Sample, (complex(r[0], r[1]), complex(dr[0], dr[1]), stamp)),
                           _new(Sample, (complex(pos[0], pos[1]), complex(vel[0], vel[1]),
                                         msg.vehicle_stamp_s)),
                           fields))

    def ready(self, setup: Setup) -> bool:
        """True once every observed target and every neighbour and the successor was heard."""
        targets, peers = self.targets, self.peers
        return all(j in targets for j in setup.observed) and all(j in peers for j in setup.peers)

    def stale(self, setup: Setup, peers: Mapping[int, Peer], now_s: float) -> int:
        """How many of the inputs of a step are missing or older than `setup.stale_s`."""
        limit, targets = setup.stale_s, self.targets
        old = sum(1 for j in setup.observed
                  if j not in targets or now_s - targets[j].stamp_s > limit)
        return old + sum(1 for j in setup.peers if now_s - peers[j].r.stamp_s > limit)

    def regroup(self, setup: Setup) -> None:
        """Forget targets no longer observed and peers no longer members: a departed peer's
        last message (and link sums) must not outlive it; if it comes back, it is a new
        process whose links start from zero."""
        members = set(setup.members)
        self.targets = {j: s for j, s in self.targets.items() if j in setup.observed}
        self.filters = {j: f for j, f in self.filters.items() if j in setup.observed}
        self.peers = {j: p for j, p in self.peers.items() if j in members}
        self.gate.forget()

