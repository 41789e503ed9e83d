"""A vanished minority leaves the ring once settled; half the ring or more vanishing at
once (a partition's far side) is held, and leaves only if it is not back within the hold."""

from __future__ import annotations

import pytest

from agents.membership.member_hold import HOLD_S, SETTLE_S, MemberHold

ALL = frozenset({0, 1, 2, 3})


def test_a_minority_that_vanished_leaves_once_settled_and_comes_back_at_once() -> None:
    hold = MemberHold(decided=ALL)
    assert hold.members(frozenset({0, 1, 3}), 10.0) == ALL  # settling: still a member
    assert hold.members(frozenset({0, 1, 3}), 10.0 + 0.9 * SETTLE_S) == ALL
    assert hold.members(frozenset({0, 1, 3}), 10.0 + SETTLE_S) == {0, 1, 3}
    assert hold.members(ALL, 20.0) == ALL and hold.holds == 0


def test_half_the_ring_vanishing_together_is_held_and_never_leaves_if_back_in_time() -> None:
    hold = MemberHold(decided=ALL)
    half = frozenset({0, 1})
    for t in (40.0, 40.0 + SETTLE_S, 40.0 + HOLD_S - 0.1):
        assert hold.members(half, t) == ALL, t
    assert hold.holds == 1
    assert hold.members(ALL, 40.0 + HOLD_S - 0.05) == ALL
    assert not hold.held and not hold.pending
    # A second cut later is judged afresh
    hold.members(half, 100.0)
    assert hold.members(half, 100.0 + SETTLE_S) == ALL and hold.holds == 2


def test_a_held_group_not_back_within_the_hold_leaves() -> None:
    hold = MemberHold(decided=ALL)
    assert hold.members(frozenset({2}), 0.0) == ALL  # follower 2 cut off alone: it holds
    assert hold.members(frozenset({2}), HOLD_S - 0.01) == ALL
    assert hold.members(frozenset({2}), HOLD_S) == {2}


@pytest.mark.parametrize(("gone_first", "gone_later", "held"), [
    ({3}, {2}, True),  # within the settling time: one vanishing of half the ring
    ({3}, set(), False),
])
def test_followers_vanishing_within_the_settling_time_count_as_one_group(
        gone_first: set[int], gone_later: set[int], held: bool) -> None:
    hold = MemberHold(decided=ALL)
    hold.members(ALL - gone_first, 5.0)
    hold.members(ALL - gone_first - gone_later, 5.0 + 0.5 * SETTLE_S)
    after = hold.members(ALL - gone_first - gone_later, 5.0 + 1.01 * SETTLE_S)
    assert (after == ALL) is held
    assert after == (ALL if held else ALL - gone_first)


def test_a_newcomer_joins_at_once_and_the_first_call_takes_the_tokens() -> None:
    hold = MemberHold()
    assert hold.members(frozenset({0}), 0.0) == {0}
    assert hold.members(frozenset({0, 2}), 0.1) == {0, 2}
