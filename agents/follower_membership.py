"""A follower's side of a membership change: pure (agents.membership gives the new ring).

- `regroup` carries the memory over to the new links (robust link sums: kept, dropped or
  new at zero, so sum(Phi) stays 0) and asks the next tick to keep r_i continuous
  (agents.estimate_carry).
- `with_missing` lets a follower that has run keep running while a new neighbour or
  successor is not heard yet: the peer counts as missing (its link carries no flow, the
  spacing term waits), instead of stopping the estimator and hovering.
- `join_running` starts a follower that (re)joins a running swarm from its neighbours'
  estimate instead of from p~_i (which for a follower that observes no target is the
  origin, as far from the LAP as the swarm has flown).
- `standing_estimate` is what a follower publishes while it cannot run the estimator.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from agents.follower_logic import (
    FloatArray,
    FollowerMemory,
    FollowerSetup,
    PeerView,
    Sample,
    reference,
)

# A missing peer's stand-in is this old: past every hold and staleness limit.
_MISSING_AGE_S = 1.0e6


def standing_estimate(memory: FollowerMemory, setup: FollowerSetup, now_s: float) -> FloatArray:
    """What a follower publishes as r_i while it cannot run the estimator (not `ready`):
    p~_i before it ever ran (so that neighbours get ready), afterwards its last r_i held.
    Publishing p~_i mid-run (a new neighbour not heard yet, just after a membership change)
    would throw the ring by as much as the LAP's distance from the origin."""
    if memory.last_r is None:
        return reference(memory, setup, now_s)[0]
    return memory.last_r.held(now_s, setup.hold_after_s)


def regroup(memory: FollowerMemory, old: FollowerSetup, new: FollowerSetup) -> FollowerMemory:
    """The memory carried across a membership change from `old` to `new` links.

    A kept link keeps its running sum; a dropped link's sum is dropped (its other end
    drops its own, or is gone), a new link starts at zero: every link still counts
    0.5 (S_ij - S_ji) at one end and the opposite at the other, so sum(Phi) stays 0
    (robust estimator).  The paper's Phi has no per-link parts and is kept whole.
    Tracks of targets no longer observed and ages of departed peers are dropped.
    """
    peers = set(new.neighbours) | {new.successor}
    ages = {j: a for j, a in memory.peer_age_s.items() if j in peers}
    targets = {j: s for j, s in memory.targets.items() if j in new.observed}
    # r_i jumps with the new links and weights: the next tick carries it over instead.
    memory = replace(memory, peer_age_s=ages, targets=targets, rebase_pending=True)
    if memory.link_sums_m is None or memory.link_rates_m_s is None:
        return memory
    m = memory
    return replace(m, link_sums_m=_per_new_link(m.link_sums_m, old, new),
                   link_rates_m_s=_per_new_link(m.link_rates_m_s, old, new),
                   vel_sums_m_s=_per_new_link(m.vel_sums_m_s, old, new),
                   vel_rates_m_s2=_per_new_link(m.vel_rates_m_s2, old, new))


def _per_new_link(per_old: FloatArray | None, old: FollowerSetup,
                  new: FollowerSetup) -> FloatArray | None:
    """(d_new, 2): a kept link's row, zero for a new link; None stays None."""
    if per_old is None:
        return None
    out = np.zeros((len(new.neighbours), 2))
    for k, j in enumerate(new.neighbours):
        if j in old.neighbours:
            out[k] = per_old[old.neighbours.index(j)]
    return out


def with_missing(peers: dict[int, PeerView], setup: FollowerSetup, memory: FollowerMemory,
                 now_s: float) -> dict[int, PeerView]:
    """`peers` with a stand-in for every neighbour or successor not heard yet: stamped long
    ago at our own last estimate and position, so that `follower_tick` treats it as missing."""
    needed = (set(setup.neighbours) | {setup.successor}) - peers.keys()
    if not needed or memory.last_r is None:
        return peers
    old = now_s - _MISSING_AGE_S
    stand_in = PeerView(Sample(memory.last_r.value, np.zeros(2), old),
                        Sample(memory.last_r.value, np.zeros(2), old))
    return {**peers, **dict.fromkeys(needed, stand_in)}


def join_running(memory: FollowerMemory, setup: FollowerSetup, peers: dict[int, PeerView],
                 now_s: float) -> FollowerMemory:
    """A follower (re)joining a running swarm: its first estimate continues the mean of its
    heard neighbours' estimates (unchanged if none is heard yet, or it has run before)."""
    if memory.last_r is not None:  # every tick once it has run: nothing to build
        return memory
    heard = [peers[j].r for j in setup.neighbours if j in peers]
    if not heard:
        return memory
    value = np.mean([s.held(now_s, setup.hold_after_s) for s in heard], axis=0)
    rate = np.mean([s.held_rate(now_s, setup.hold_after_s) for s in heard], axis=0)
    return replace(memory, last_r=Sample(value, rate, now_s), rebase_pending=True)
