"""Naming a liar from the followers' own counts (deploy.report.liars)."""

from __future__ import annotations

import pytest

from deploy.report.liars import accused, liar_lines

pytestmark = pytest.mark.timeout(30)


def test_two_accusers_name_one_suspects() -> None:
    status = {
        "follower-0": {"implausible_f1": 40, "implausible_first_ms_f1": 20048},
        "follower-2": {"implausible_f1": 38, "implausible_first_ms_f1": 20052},
        "follower-1": {"implausible_f3": 5, "implausible_first_ms_f3": 3000},  # blame
        "follower-3": {"states_sent": 10},
        "sim-0": {"implausible_f2": 99},  # not a follower's word
    }
    (liar, suspect) = accused(status)
    assert liar.index == 1 and liar.named and liar.rejected == 78 and liar.first_s == 20.048
    assert suspect.index == 3 and not suspect.named
    lines = liar_lines({"status_at_stop": status})
    assert lines[0].startswith("follower-1 (the scenario's follower 2) lied: 78 states")
    assert "20.05 s" in lines[0] and "suspected by follower-1 only" in lines[1]


def test_nobody_refused_nobody_named() -> None:
    assert liar_lines({"status": {"follower-0": {"implausible_f1": 0}}}) == ()
    assert liar_lines({}) == ()
