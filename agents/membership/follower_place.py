"""A follower's place in the swarm its members form, and what a change of members asks.

`setup_for` is the law's `Setup` from the member set (agents.membership.ring forms the ring),
numpy-free: the follower process builds one at every change of members and must not
import numpy (issue 15: <= 50 MB per follower); tests/unit/test_follower_setup.py pins its
weights and edge fractions to the lock-step engine's matrices (agents.lockstep.estimator_weights).
`stand_ins` fills a link not heard yet, `joined_estimate` is where a follower (re)joining
a running swarm continues from; agents.follower.runner carries the law across a change.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from agents.law.interface import Peer, Sample, Setup
from agents.membership.ring import membership
from agents.scenario.model import Scenario

# An input older than this is missing (no flow on its link, no spacing to it): the
# vehicle link's timeout.
STALE_AFTER_S = 0.5
# The longest extrapolation of any input: a stall of the data (a scheduling hiccup, a
# simulator catching up) is bridged, a long silence is not flown on a guess.
HOLD_AFTER_S = 1.0
# The longest dt one step integrates: a paused process does not integrate a jump.
MAX_GAP_S = 0.25
# The platform's filter of a target's velocity (agents.follower.inputs): its time
# constant, and that of the acceleration that undoes its lag.
TARGET_VEL_TAU_S = 0.1
TARGET_ACCEL_TAU_S = 0.5


def setup_for(scenario: Scenario, index: int, members: Iterable[int] | None = None) -> Setup:
    """Follower `index`'s share of the swarm formed by `members` (default: everyone)."""
    form = membership(scenario, range(scenario.n) if members is None else members)
    row = form.weight_row(index)
    nbrs = form.neighbours(index)
    successor = form.successor[index]
    return Setup(
        index=index,
        members=form.members,
        neighbours=nbrs,
        successor=successor,
        peers=tuple(sorted(set(nbrs) | {successor})),
        observed=tuple(j for j, w in enumerate(row) if w != 0.0),
        weights=tuple((j, float(w)) for j, w in enumerate(row) if w != 0.0),
        nbr_fractions=tuple(form.edge_fraction(index, j) for j in nbrs),
        angle_rad=form.angles_rad[index],
        rho_d_m=scenario.pattern.rho_d_m,
        w_d_rad_s=scenario.pattern.w_d_rad_s,
        period_s=1.0 / scenario.run.rate_hz,
        est_period_s=1.0 / scenario.run.estimator_hz,
        hold_s=HOLD_AFTER_S,
        stale_s=STALE_AFTER_S,
        max_gap_s=MAX_GAP_S,
    )


# A missing peer's stand-in is this old: past every hold and staleness limit.
MISSING_AGE_S = 1.0e6


def stand_ins(peers: Mapping[int, Peer], setup: Setup, own: Sample | None, now_s: float,
              ) -> Mapping[int, Peer]:
    """`peers` with a stand-in for every neighbour or successor not heard yet (a new link,
    after a change of members): this follower's own estimate `own`, too old to count."""
    if own is None:
        return peers
    for j in setup.peers:
        if j not in peers:
            break
    else:
        return peers
    old = now_s - MISSING_AGE_S
    value = own.value
    stand_in = Peer(Sample(value, 0j, old), Sample(value, 0j, old), {})
    return {**peers, **{j: stand_in for j in setup.peers if j not in peers}}


def joined_estimate(peers: Mapping[int, Peer], setup: Setup, now_s: float) -> Sample | None:
    """Where a follower (re)joining a running swarm continues from: its heard neighbours'
    mean estimate and rate (held to now); None while it heard none.  Its own p~ would
    throw the running ring."""
    heard = [peers[j].r for j in setup.neighbours if j in peers]
    if not heard:
        return None
    hold = setup.hold_s
    value = sum((s.held(now_s, hold) for s in heard), 0j) / len(heard)
    rate = sum((s.held_rate(now_s, hold) for s in heard), 0j) / len(heard)
    return Sample(value, rate, now_s)
