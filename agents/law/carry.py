"""A follower's estimate stays continuous across a membership change: pure.

When the member set changes, a follower's p~_i (targets re-assigned, weights re-balanced)
and its Phi_i (a dropped link's running sums leave, robust estimator) change at once, so
r_i = p~_i + Phi_i jumps -- by up to the LAP's distance from the origin for a follower that
observes no target (measured: 15 m, 30 s into the paper's case, after a kill).  The ring
would fly that jump.  Instead, at its first tick after the change, the follower puts the
jump into a carry c_i added to r_i, which then decays with time constant `tau_s`: r_i is
continuous, and the consensus re-forms Phi_i under it while c_i fades.

Why this keeps the estimator right: the carry is the follower's own and never enters a
link sum, so sum(Phi) stays zero; once every c_i has decayed, mean(r) = mean(p~) (the LAP)
again, exactly as without it.  With the robust estimator sum(c) is about zero from the
start (the old r_i agreed on the LAP, and so does the new mean of p~ + Phi).
"""

from __future__ import annotations

import math

REBASE_TAU_S = 3.0


def next_carry(
    carry_m: complex,
    raw_r_m: complex,
    continue_from_m: complex | None,
    dt_s: float,
    tau_s: float = REBASE_TAU_S,
) -> complex:
    """The carry c_i of this step (r_i = raw + c_i, dr_i/dt = raw rate - c_i / tau_s), plane
    vectors as complex x + iy.

    `continue_from_m` (the previous r_i carried to now: the platform's `Inputs.rebase_to`)
    is given at the first step after a change: c_i is set so that r_i equals it.
    Otherwise c_i decays over dt_s.  The consensus must act on r_i with its carry: acting
    on the raw part would pull each raw part towards the neighbours' carried r_j and undo
    the continuity.
    """
    if continue_from_m is not None:
        return continue_from_m - raw_r_m
    return carry_m * math.exp(-dt_s / tau_s)
