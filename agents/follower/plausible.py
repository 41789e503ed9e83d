"""Per-neighbour plausibility: a neighbour's state that no honest follower could have sent.

A message that passed the transport's checks (valid keys, in bounds, from its key's
owner) can still be a lie by that owner (issue 51: the `lie` fault, agents.follower.lie).
A follower holds each neighbour j's message against what the swarm's physics and the
law's own dynamics allow, and against what it knows itself, before its law sees it:

- jump:     r_j against j's last accepted r extrapolated by its own rate: an honest
            estimate is continuous (agents.law.carry keeps it so across every change),
            so it lands within `jump_m`, plus `slack_m_s` per second since that message
            (the targets' centre moves at most beta; an excluded neighbour comes back);
- agree:    r_j against this follower's own estimate: past the settling time, honest
            estimates agree to the paper's eps; `agree_m` is well above that;
- geometry: r_j against this follower's own target observation: its weighted target
            position p~_i over its weight sum is a convex combination of targets, so it
            lies within the targets' spread of their centre, and the scenario is admitted
            only if that spread is below rho_d (agents.scenario.checks): an honest r_j is
            within rho_d + eps of it, whatever the other neighbours say;
- link:     for a field a law declares `odd` (the robust estimator's link sums), a
            link's two ends cancel (S_ij + S_ji ~ 0, agents.law.consensus.link_balance):
            their sum d may move by `link_m`, plus `link_slack_m_s` per second since j's
            last accepted message (its end integrates while ours is cut off from it).

A message that fails one is dropped before the law sees it, and counted per sender and
reason; the neighbour's last accepted message then ages, and past `Setup.stale_s` the law
treats the link as missing (no flow on it, its link sums held, no spacing to it): the
neighbour is excluded until its messages are plausible again.  The first two checks arm
`arm_after_s` after the start (the estimators converge from p~ before).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field

from agents.law.interface import Peer, Sample, Setup, reference
from transport.law_fields import FieldSpec, LawFields

REASONS = ("jump", "agree", "geometry", "link")


@dataclass(frozen=True)
class GateLimits:
    """The thresholds, metres and m/s (chosen by measurement: docs/security.md)."""

    jump_m: float = 2.0
    slack_m_s: float = 2.5
    agree_m: float = 3.0
    geometry_m: float = 9.0
    link_m: float = 2.0
    link_slack_m_s: float = 2.5
    arm_after_s: float = 10.0


def gate_limits(rho_d_m: float, beta_m_s: float) -> GateLimits:
    """The paper case's measured margins, scaled to a scenario's radius and speed bound."""
    return GateLimits(slack_m_s=2.0 * beta_m_s + 0.25, geometry_m=rho_d_m + 1.0,
                      link_slack_m_s=2.0 * beta_m_s + 0.25)


@dataclass
class _Track:
    """What one neighbour was last believed: its message and its links' sums d."""

    r: Sample
    sums: dict[str, complex]  # odd field -> S_ij + S_ji at the message
    accepted_s: float
    heard_s: float  # its last message, plausible or not: a silence is not a lie


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
                 hold_s: float) -> None:
        self.index, self.limits, self.odd, self.hold_s = index, limits, odd, hold_s
        self.own = Own()
        self.origin_s: float | None = None  # the experiment's start: detection times
        self._tracks: dict[int, _Track] = {}
        self.counters: Counter[str] = Counter()

    def check(self, sender: int, peer: Peer, now_s: float) -> str | None:
        """None if `peer` (sender's newest message) is plausible, else why not (counted)."""
        track = self._tracks.get(sender)
        if track is not None and now_s - track.heard_s > self.hold_s:
            track = None  # silent for a while (a restart, a cut): a fresh start
        sums = self._sums(sender, peer, now_s)
        why = self._reason(track, peer, sums, now_s)
        if why is None:
            self._tracks[sender] = _Track(peer.r, sums, now_s, now_s)
            return None
        if track is not None:
            track.heard_s = now_s
        else:  # never believed: judged against no history, and the silence rule holds
            self._tracks[sender] = _Track(peer.r, sums, -1e18, now_s)
        self._count(sender, why, now_s)
        return why

    def forget(self) -> None:
        """A change of members: links are new (their sums restart), history goes."""
        self._tracks = {}

    def _reason(self, track: _Track | None, peer: Peer, sums: Mapping[str, complex],
                now_s: float) -> str | None:
        lim, own = self.limits, self.own
        r = peer.r.value
        if track is not None and track.accepted_s > -1e17:
            age = max(peer.r.stamp_s - track.r.stamp_s, 0.0)
            jump = abs(r - track.r.at(peer.r.stamp_s)) - lim.slack_m_s * age
            if self._over("jump", jump, lim.jump_m):
                return "jump"
            allowed = lim.link_slack_m_s * max(now_s - track.accepted_s, 0.0)
            for name, d in sums.items():
                ref = track.sums.get(name)
                if ref is not None and self._over("link", abs(d - ref) - allowed, lim.link_m):
                    return "link"
        if not own.armed:
            return None
        at = peer.r.at(now_s)
        if own.r is not None and self._over("agree", abs(at - own.r.at(now_s)), lim.agree_m):
            return "agree"
        if own.centre is not None and self._over("geometry", abs(at - own.centre),
                                                 lim.geometry_m):
            return "geometry"
        return None

    def _over(self, check: str, value: float, limit: float) -> bool:
        """True past `limit`; the largest value passed is kept (`plausible_max_mm_<check>`:
        the honest margin the thresholds were chosen on)."""
        if value > limit:
            return True
        key = f"plausible_max_mm_{check}"
        mm = round(value * 1000.0)
        if mm > self.counters.get(key, 0):
            self.counters[key] = mm
        return False

    def _sums(self, sender: int, peer: Peer, now_s: float) -> dict[str, complex]:
        """Per odd field: its two ends' sum on our link, both carried to now_s."""
        out = {}
        for name in self.odd:
            theirs, ours = peer.fields.get(name), self.own.sums.get(name, {}).get(sender)
            if isinstance(theirs, Sample) and ours is not None:
                out[name] = theirs.at(now_s) + ours.at(now_s)
        return out

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
