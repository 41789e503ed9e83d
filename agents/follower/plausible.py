"""Per-neighbour plausibility: a neighbour's state that no honest follower could have sent.

A message that passed the transport's checks (valid keys, in bounds, from its key's
owner) can still be a lie by that owner (issue 51: the `lie` fault, agents.follower.lie).
A follower holds each neighbour j's message against what the swarm's physics and the
law's own dynamics allow, and against what it knows itself, before its law sees it:

- rate:     a value against its own declared rate (r_j and dr_j/dt; a link sum and its
            rate): between two consecutive messages an honest value moves by its rate
            times the time between them, up to the integration's small error.  The
            differences are summed, leaking with `rate_tau_s`, each clipped at twice the
            limit: past `rate_m`, refused.  A jump (an offset, a sum set at the bound),
            a random walk: all are caught within a few messages, and a liar back to the
            truth is taken back within `rate_tau_s * ln 2`;
- frozen:   a value resent unchanged under a fresh stamp while its rate says it moves
            (a replayed or stale state; an honest sender integrates between stamps):
            `frozen_n` in a row are refused (the rate check never sees a slow one);
- jump:     r_j against where it was last believed, held there, plus `slack_m_s` per
            second since (the targets' centre moves at most beta): a silence does not
            reset it, so going quiet buys a liar no fresh start;
- link:     for a field a law declares `odd` (the robust estimator's link sums), a
            link's two ends cancel (S_ij + S_ji ~ 0, agents.law.consensus.link_balance):
            their sum d may move as `jump` allows since it was last believed, and its
            change between consecutive messages is summed the same way (`link_tau_s`,
            `link_m`): a neighbour cannot move our Phi_i faster than
            link_m / link_tau_s / 2 unseen;
- agree:    r_j against this follower's own estimate and the other neighbours' latest
            ones: past the settling time, honest estimates agree to the paper's eps, so
            r_j within `agree_m` of any one of them passes (a follower that drifted
            itself still takes two neighbours that agree with each other: no deadlock);
            a track (re)started after a silence or a change of members gets
            `arm_after_s` to converge first;
- geometry: r_j against this follower's own target observation: its weighted target
            position p~_i over its weight sum is a convex combination of targets, so it
            lies within the targets' spread of their centre, and the scenario is admitted
            only if that spread is below rho_d (agents.scenario.checks): an honest r_j is
            within rho_d + eps of it, whatever the other neighbours say.

A message that fails one is dropped before the law sees it, and counted per sender and
reason; the neighbour's last accepted message then ages, and past `Setup.stale_s` the law
treats the link as missing (no flow on it, its link sums held, no spacing to it): the
neighbour is excluded until its messages are plausible again.  The checks arm
`arm_after_s` after the start: the estimators converge from p~ before, at tens of m/s.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field

from agents.law.interface import Peer, Sample, Setup, reference
from transport.law_fields import FieldSpec, LawFields

log = logging.getLogger("enclose.follower")
REASONS = ("rate", "frozen", "jump", "link", "agree", "geometry")
# The largest honest value each check passed, in mm (`Plausibility._over`): named once,
# not formatted per message.
_MAX_KEYS = {check: f"plausible_max_mm_{check}" for check in REASONS}


@dataclass(frozen=True)
class GateLimits:
    """The thresholds, metres and seconds (chosen by measurement: docs/security.md)."""

    rate_m: float = 0.7
    rate_tau_s: float = 1.0
    jump_m: float = 2.0
    slack_m_s: float = 2.5
    link_m: float = 4.0
    link_tau_s: float = 2.0
    agree_m: float = 3.0
    geometry_m: float = 9.0
    arm_after_s: float = 10.0
    frozen_n: int = 3
    frozen_min_m: float = 1e-6  # |rate * dt| below which an unmoved value is honest


def gate_limits(rho_d_m: float) -> GateLimits:
    """The paper case's measured margins; the geometry bound is the scenario's radius."""
    return GateLimits(geometry_m=rho_d_m + 1.0)


@dataclass
class _Track:
    """One neighbour: its last accepted estimate, its last message, the leaky sums."""

    r: Sample  # last accepted
    accepted_s: float
    heard_s: float  # its last message, plausible or not: a silence is not a lie
    since_s: float  # the track's (re)start: `agree` waits arm_after_s from it
    last: dict[str, Sample]  # "r" and each odd field, as last heard
    d: dict[str, complex]  # each odd field's S_ij + S_ji, as last heard
    d_accepted: dict[str, complex]  # ... and as last accepted
    residual: dict[str, complex] = field(default_factory=dict)
    frozen: int = 0  # messages in a row with a value unmoved against its own rate


@dataclass
class Own:
    """This follower's side: its estimate, its target centre, its odd fields per link."""

    r: Sample | None = None
    centre: complex | None = None
    sums: dict[str, dict[int, Sample]] = field(default_factory=dict)
    armed: bool = False


class Plausibility:
    """The checks of follower `index` on its neighbours' states (module docstring)."""

    def __init__(self, index: int, limits: GateLimits, odd: tuple[str, ...],
                 hold_s: float, max_gap_s: float = 0.25) -> None:
        self.index, self.limits, self.odd, self.hold_s = index, limits, odd, hold_s
        self.max_gap_s = max_gap_s  # the longest step a law integrates (Setup.max_gap_s)
        self.own = Own()
        self.origin_s: float | None = None  # the experiment's start: detection times
        self._tracks: dict[int, _Track] = {}
        self.counters: Counter[str] = Counter()  # refusals (`_count`)
        # The largest value each check passed, metres: a float compared per check, turned
        # into whole mm only when the status asks (`all_counters`).
        self._largest = dict.fromkeys(REASONS, 0.0)
        self._excess = 0.0  # of the last check failed, for the log

    def check(self, sender: int, peer: Peer, now_s: float) -> str | None:
        """None if `peer` (sender's newest message) is plausible, else why not (counted)."""
        track = self._tracks.get(sender)
        heard, d = self._heard(sender, peer, now_s)
        if track is None:
            track = _Track(peer.r, -1e18, now_s, now_s, heard, d, {})
            self._tracks[sender] = track
        elif now_s - track.heard_s > self.hold_s:
            # Silent for a while (a restart, a cut): its last message is too old to hold
            # this one to, and agreement waits for it to converge; what it was last
            # believed still bounds where it can be now (`jump`, `link`).
            track.last, track.d, track.residual, track.since_s = heard, d, {}, now_s
            track.frozen = 0
        # Armed after the start's transient (estimates converging from p~ at tens of m/s,
        # a standing estimate handing over to the law's): before, nothing is refused.
        why = None
        if self.own.armed:
            why = (self._consistent(track, heard, d) or self._level(track, peer, d, now_s)
                   or self._agrees(sender, track, peer, now_s))
        episode = track.heard_s <= track.accepted_s
        track.heard_s, track.last, track.d = now_s, heard, d
        if why is None:
            track.r, track.accepted_s, track.d_accepted = peer.r, now_s, d
            return None
        if episode:  # the first refusal after an accepted message: say why
            log.warning("follower %d's state refused as implausible: %s, %.3g m over its "
                        "limit", sender, why, self._excess)
        self._count(sender, why, now_s)
        return why

    def refused(self, sender: int, now_s: float) -> bool:
        """True while `sender` is heard but its states are refused: excluded, not silent."""
        track = self._tracks.get(sender)
        return (track is not None and now_s - track.heard_s <= self.hold_s
                and track.accepted_s < track.heard_s)

    def forget(self) -> None:
        """A change of members: links are new (their sums restart, at both ends), and
        history goes."""
        self._tracks = {}

    def _consistent(self, track: _Track, heard: Mapping[str, Sample],
                    d: Mapping[str, complex]) -> str | None:
        """The rate and link checks: each value against its own rate since the last
        message, and each odd field's two ends against their last sum."""
        lim, why, still = self.limits, None, False
        for name, new in heard.items():
            old = track.last.get(name)
            if old is None or new.stamp_s <= old.stamp_s:
                continue
            dt = new.stamp_s - old.stamp_s
            if dt > self.max_gap_s:  # the sender stalled: it integrated less than this
                continue
            still = still or (new.value == old.value
                              and abs(old.rate) * dt > lim.frozen_min_m)
            miss = new.value - old.value - old.rate * dt
            if self._leak(track, name, miss, dt, lim.rate_tau_s, "rate", lim.rate_m):
                why = why or "rate"
        track.frozen = track.frozen + 1 if still else 0
        if track.frozen >= lim.frozen_n:
            why = "frozen"
        dt = max(heard["r"].stamp_s - track.last["r"].stamp_s, 0.0)
        for name, now_d in d.items():
            was = track.d.get(name)
            if was is not None and self._leak(track, "d_" + name, now_d - was, dt,
                                              lim.link_tau_s, "link", lim.link_m):
                why = why or "link"
        return why

    def _level(self, track: _Track, peer: Peer, d: Mapping[str, complex],
               now_s: float) -> str | None:
        """Where it was last believed bounds where it can be: r_j by `jump_m` plus
        `slack_m_s` per second since (the centre moves at most beta; an excluded
        neighbour's estimate follows it), each odd field's two ends likewise."""
        if track.accepted_s < -1e17:
            return None
        lim = self.limits
        allowed = lim.jump_m + lim.slack_m_s * max(now_s - track.accepted_s, 0.0)
        # Held, not extrapolated, past the hold: a rate taken at one instant (the
        # estimator's flows swing by m/s) would carry the reference off over a long gap.
        moved = abs(peer.r.value - track.r.held(peer.r.stamp_s, self.hold_s))
        if self._over("jump", moved - allowed + lim.jump_m, lim.jump_m):
            return "jump"
        for name, now_d in d.items():
            was = track.d_accepted.get(name)
            if was is not None and self._over("link", abs(now_d - was) - allowed + lim.jump_m,
                                              lim.jump_m):
                return "link"
        return None

    def _leak(self, track: _Track, key: str, miss: complex, dt: float, tau_s: float,
              check: str, limit: float) -> bool:
        """Add `miss` (clipped at twice the limit) to the track's leaky sum `key`: True
        if `miss` alone or that sum is past `limit`."""
        size = abs(miss)
        if size > 2.0 * limit:
            miss *= 2.0 * limit / size
        total = track.residual.get(key, 0j) * math.exp(-dt / tau_s) + miss
        track.residual[key] = total
        summed = abs(total)
        return self._over(check, summed if summed > size else size, limit)

    def _agrees(self, sender: int, track: _Track, peer: Peer, now_s: float) -> str | None:
        """The agreement and geometry checks."""
        lim, own = self.limits, self.own
        at = peer.r.at(now_s)
        settled = now_s - track.since_s >= lim.arm_after_s
        if settled and self._over("agree", self._nearest(sender, at, now_s), lim.agree_m):
            return "agree"
        if own.centre is not None and self._over("geometry", abs(at - own.centre),
                                                 lim.geometry_m):
            return "geometry"
        return None

    def _nearest(self, sender: int, at: complex, now_s: float) -> float:
        """The distance from `at` to the nearest of this follower's own estimate and its
        other neighbours' latest ones, refused or not (heard within the hold): one liar
        cannot make two honest neighbours refuse each other; two liars around one
        follower can vouch for each other."""
        nearest: float | None = None
        if self.own.r is not None:
            nearest = abs(at - self.own.r.at(now_s))
        hold_s = self.hold_s
        for j, t in self._tracks.items():
            if j != sender and now_s - t.heard_s <= hold_s:
                far = abs(at - t.last["r"].at(now_s))
                if nearest is None or far < nearest:
                    nearest = far
        return 0.0 if nearest is None else nearest

    def _over(self, check: str, value: float, limit: float) -> bool:
        """True past `limit`; the largest value passed is kept (`plausible_max_mm_<check>`:
        the honest margin the thresholds were chosen on)."""
        if value > limit:
            self._excess = value - limit
            return True
        if value > self._largest[check]:
            self._largest[check] = value
        return False

    def all_counters(self) -> dict[str, int]:
        """The refusals (`implausible_*`) and, per check that passed a value of 1 mm or
        more, the largest (`plausible_max_mm_<check>`)."""
        largest = {_MAX_KEYS[c]: mm for c, v in self._largest.items()
                   if (mm := round(v * 1000.0)) > 0}
        return {**self.counters, **largest}

    def _heard(self, sender: int, peer: Peer,
               now_s: float) -> tuple[dict[str, Sample], dict[str, complex]]:
        """What is checked of `peer`: r and each odd field it holds, and per odd field its
        two ends' sum on our link, both carried to now_s (one pass: every message)."""
        heard, d = {"r": peer.r}, {}
        fields, sums = peer.fields, self.own.sums
        for name in self.odd:
            theirs = fields.get(name)
            if isinstance(theirs, Sample):
                heard[name] = theirs
                ours = sums[name].get(sender) if name in sums else None
                if ours is not None:
                    d[name] = theirs.at(now_s) + ours.at(now_s)
        return heard, d

    def _count(self, sender: int, why: str, now_s: float) -> None:
        c = self.counters
        c[f"implausible_f{sender}"] += 1
        c[f"implausible_{why}"] += 1
        first = f"implausible_first_ms_f{sender}"
        if first not in c and self.origin_s is not None:
            c[first] = max(round((now_s - self.origin_s) * 1000.0), 1)


def own_side(r: Sample | None, setup: Setup, targets: Mapping[int, Sample], now_s: float,
             wire: LawFields, specs: Mapping[str, FieldSpec], armed: bool) -> Own:
    """This follower's side after a step: its estimate, the centre of its own targets
    (p~_i over its weight sum: a convex combination of targets), and its odd fields as
    published (per neighbour, a Sample of value and declared rate)."""
    total = sum(w for _, w in setup.weights)
    centre = reference(setup, targets, now_s)[0] / total if total > 0.0 else None
    sums: dict[str, dict[int, Sample]] = {}
    for name, spec in specs.items():
        if spec.odd and name in wire:
            rates = _per_link(wire.get(spec.rate)) if spec.rate else {}
            sums[name] = {j: Sample(v, rates.get(j, 0j), now_s)
                          for j, v in _per_link(wire[name]).items()}
    return Own(r, centre, sums, armed)


def _per_link(value: object) -> dict[int, complex]:
    """A per_link field as published ((j, x, y), ...), by neighbour."""
    if not isinstance(value, tuple):
        return {}
    return {int(link[0]): complex(link[1], link[2]) for link in value
            if isinstance(link, tuple) and len(link) == 3}
