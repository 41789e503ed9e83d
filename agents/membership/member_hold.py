"""Which of the followers whose tokens vanished leave the ring now, and which are held:
pure, time is an argument.

A follower cannot tell a crash of the others from a cut of its own network.  When a
minority of the ring vanishes (a crash, a follower cut off alone) the ring re-forms
without them, as it always did.  When half of the ring or more vanishes at once, the
follower may be on one side of a partition, and re-forming would do harm: each side
spreads its own spacing over 360 deg around its own estimate, so the two sides fly into
each other's places (measured on the paper's case, {1, 2} | {3, 4} for 15 s: closest
approach 0.23 m), and at the heal the ring re-forms once more and its estimates restart
on new links (16.9 s back inside the bounds).  So such a group is *held*: it stays in the
member set, its links silent (their data are stale, so the law runs no flow on them and
flies a missing successor's place as planned, agents.law.paper) for up to HOLD_S; if it
is back by then the ring never changed, otherwise it leaves then.

One vanishing is the followers whose tokens vanish within SETTLE_S of the first
(a partition's tokens vanish together: one lost session, or one instant of a scripted
cut); they count against the member set before it.  Until the decision a vanished
follower stays a member, so a crash re-forms the ring SETTLE_S later than its token
vanished (its data are stale by then anyway: agents.membership.follower_place.STALE_AFTER_S).

The price: a ring whose half really crashed flies with a gap, and without the targets
only the lost half observed, for HOLD_S before it re-forms.
"""

from __future__ import annotations

from dataclasses import dataclass, field

SETTLE_S = 0.5
# Longer than the partitions the shipped sweep scripts (bench/sweeps/partition.toml: up
# to 30 s); a longer one re-forms the ring as before.
HOLD_S = 30.0


@dataclass
class MemberHold:
    """The member set from the token set, with vanished groups decided as above."""

    settle_s: float = SETTLE_S
    hold_s: float = HOLD_S
    decided: frozenset[int] | None = None  # the member set last returned
    pending: dict[int, float] = field(default_factory=dict)  # vanished at, undecided
    held: dict[int, float] = field(default_factory=dict)  # held until
    holds: int = 0  # vanishings held (a partition's side, by this rule)

    def members(self, tokens: frozenset[int], now_s: float) -> frozenset[int]:
        """The member set at `now_s`, given the followers whose tokens live now."""
        if self.decided is None:
            self.decided = tokens
            return tokens
        for waiting in (self.pending, self.held):
            for i in [i for i in waiting if i in tokens]:
                del waiting[i]  # back: it never left the ring
        for i in sorted(self.decided - tokens - set(self.pending) - set(self.held)):
            self.pending[i] = now_s
        dropped = self._decide(now_s)
        dropped |= {i for i, until in self.held.items() if now_s >= until}
        for i in dropped:
            self.held.pop(i, None)
        self.decided = (self.decided - dropped) | tokens
        return self.decided

    def _decide(self, now_s: float) -> set[int]:
        """The pending vanishing, once settled: the followers it drops (none when held)."""
        if not self.pending:
            return set()
        first_s = min(self.pending.values())
        if now_s - first_s < self.settle_s:
            return set()
        group = set(self.pending)
        self.pending.clear()
        assert self.decided is not None
        if 2 * len(group) >= len(self.decided):
            self.holds += 1
            self.held.update({i: first_s + self.hold_s for i in group})
            return set()
        return group
