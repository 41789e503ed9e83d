"""agents.follower_membership for the fast follower (agents.follower_fast): the same four
functions on its complex-vector memory, pinned to the reference by
tests/unit/test_follower_fast.py.  Why each does what it does: see the reference."""

from __future__ import annotations

from collections.abc import Mapping

from agents.follower_fast import FastSetup, FollowerMemory, PeerView, Sample, reference

# A missing peer's stand-in is this old: past every hold and staleness limit.
_MISSING_AGE_S = 1.0e6


def standing_estimate(memory: FollowerMemory, setup: FastSetup, now_s: float) -> complex:
    """What a follower publishes as r_i while it cannot run the estimator (not `ready`)."""
    if memory.last_r is None:
        return reference(memory, setup, now_s)[0]
    return memory.last_r.held(now_s, setup.ref.hold_after_s)


def regroup(memory: FollowerMemory, old: FastSetup, new: FastSetup) -> FollowerMemory:
    """The memory carried across a membership change from `old` to `new` links."""
    peers = set(new.peers)
    ages = {j: a for j, a in memory.peer_age_s.items() if j in peers}
    targets = {j: s for j, s in memory.targets.items() if j in new.observed}
    kept = {j: k for k, j in enumerate(old.neighbours)}

    def per_new_link(per_old: tuple[complex, ...] | None) -> tuple[complex, ...] | None:
        if per_old is None:
            return None
        return tuple(per_old[kept[j]] if j in kept else 0j for j in new.neighbours)

    m = memory
    return m._replace(peer_age_s=ages, targets=targets, rebase_pending=True,
                      link_sums_m=per_new_link(m.link_sums_m),
                      link_rates_m_s=per_new_link(m.link_rates_m_s),
                      vel_sums_m_s=per_new_link(m.vel_sums_m_s),
                      vel_rates_m_s2=per_new_link(m.vel_rates_m_s2))


def with_missing(peers: Mapping[int, PeerView], setup: FastSetup, memory: FollowerMemory,
                 now_s: float) -> Mapping[int, PeerView]:
    """`peers` with a stand-in for every neighbour or successor not heard yet."""
    if memory.last_r is None or all(j in peers for j in setup.peers):
        return peers
    old = now_s - _MISSING_AGE_S
    value = memory.last_r.value
    stand_in = PeerView(Sample(value, 0j, old), Sample(value, 0j, old))
    return {**peers, **{j: stand_in for j in setup.peers if j not in peers}}


def join_running(memory: FollowerMemory, setup: FastSetup, peers: Mapping[int, PeerView],
                 now_s: float) -> FollowerMemory:
    """A follower (re)joining a running swarm continues its heard neighbours' mean estimate."""
    if memory.last_r is not None:
        return memory
    heard = [peers[j].r for j in setup.neighbours if j in peers]
    if not heard:
        return memory
    hold = setup.ref.hold_after_s
    value = sum((s.held(now_s, hold) for s in heard), 0j) / len(heard)
    rate = sum((s.held_rate(now_s, hold) for s in heard), 0j) / len(heard)
    return memory._replace(last_r=Sample(value, rate, now_s), rebase_pending=True)
