"""Membership: the ring re-forms deterministically around leavers, and the graph stays whole."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.loading.scenario_file import load_scenario, parse_scenario
from agents.membership.ring import membership, ring_order
from agents.scenario.model import Scenario
from errors import InadmissibleError

PAPER = load_scenario("paper")
RING16 = load_scenario("ring16")


def connected(members: tuple[int, ...], edges: tuple[tuple[int, int], ...]) -> bool:
    seen, frontier = {members[0]}, [members[0]]
    while frontier:
        a = frontier.pop()
        for x, y in edges:
            for b in ((y,) if x == a else (x,) if y == a else ()):
                if b not in seen:
                    seen.add(b)
                    frontier.append(b)
    return seen == set(members)


def keep(s: Scenario) -> Scenario:
    return dataclasses.replace(s, pattern=dataclasses.replace(s.pattern, rebalance="keep"))


def test_full_membership_is_the_scenario() -> None:
    form = membership(PAPER, range(4))
    assert form.edges == PAPER.edges
    assert [form.successor[i] for i in range(4)] == list(PAPER.successor)
    assert [form.angles_rad[i] for i in range(4)] == pytest.approx(PAPER.pattern.angles_rad)
    np.testing.assert_allclose(form.weights(), [[1, 0], [1, 0], [0, 1], [0, 1]])


def test_ring_leaver_neighbours_link_and_successor_skips_it() -> None:
    form = membership(PAPER, [1, 2, 3])  # follower 1 of the paper (index 0) left
    assert form.edges == ((1, 2), (1, 3), (2, 3))
    assert form.successor == {1: 2, 2: 3, 3: 1}
    assert form.neighbours(3) == (1, 2)
    # scale: (72, 72, 144) * 360 / 288
    degs = [math.degrees(form.angles_rad[i]) for i in (1, 2, 3)]
    assert degs == pytest.approx([90.0, 90.0, 180.0])
    # target 0 still seen by follower 1 alone: weight n/m/1 = 1.5; mean p~ is the LAP
    np.testing.assert_allclose(form.weights()[[1, 2, 3]], [[1.5, 0], [0, 0.75], [0, 0.75]])


def test_keep_merges_the_gap_into_the_predecessor() -> None:
    form = membership(keep(PAPER), [0, 2, 3])  # index 1 left; 0 was its predecessor
    degs = {i: math.degrees(a) for i, a in form.angles_rad.items()}
    assert degs == pytest.approx({0: 144.0, 2: 72.0, 3: 144.0})
    form = membership(keep(PAPER), [1, 2, 3])  # index 0 left; 3 precedes it (wrap-around)
    degs = {i: math.degrees(a) for i, a in form.angles_rad.items()}
    assert degs == pytest.approx({1: 72.0, 2: 72.0, 3: 216.0})


def test_orphan_target_goes_to_the_next_member_in_ring_order() -> None:
    form = membership(PAPER, [2, 3])  # both observers of target 0 left
    assert form.observers == ((2,), (2, 3))
    np.testing.assert_allclose(form.weights()[[2, 3]].sum(axis=0), [1.0, 1.0])


def test_uniform_ring_stays_uniform_and_consecutive_leavers_bridge() -> None:
    order = ring_order(RING16.successor)
    absent = {order[3], order[4], order[5], order[11]}  # three in a row, and one apart
    form = membership(RING16, [i for i in range(16) if i not in absent])
    assert list(form.angles_rad.values()) == pytest.approx([2 * math.pi / 12] * 12)
    before, after = order[2], order[6]
    assert (min(before, after), max(before, after)) in form.edges
    assert form.successor[before] == after


def test_rebalance_is_validated_naming_the_field() -> None:
    text = (
        'beta_m_s = 1.0\n[pattern]\nrho_d_m = 8.0\nrebalance = "squash"\n'
        "[[followers]]\npos_m = [10.0, 0.0]\n[[followers]]\npos_m = [-10.0, 0.0]\n"
        '[[targets]]\npos_m = [0.0, 0.0]\nprofile = "constant"\nobserved_by = [1]\n'
    )
    with pytest.raises(InadmissibleError, match=r"pattern\.rebalance"):
        parse_scenario(text)


def test_membership_refuses_empty_or_unknown() -> None:
    with pytest.raises(ValueError):
        membership(PAPER, [])
    with pytest.raises(ValueError):
        membership(PAPER, [0, 7])


def random_graph_scenario(n: int, extra: list[tuple[int, int]], seed: int) -> Scenario:
    """A ring of n plus chords, followers on a circle, targets watched by random followers."""
    rng = np.random.default_rng(seed)
    edges = {(i, (i + 1) % n) for i in range(n)} | {(a % n, b % n) for a, b in extra}
    edges = {(min(a, b), max(a, b)) for a, b in edges if a % n != b % n}
    pos = [[20 * math.cos(2 * math.pi * k / n), 20 * math.sin(2 * math.pi * k / n)]
           for k in range(n)]
    lines = ["beta_m_s = 1.0", "[pattern]", "rho_d_m = 8.0", "[graph]",
             f"edges = {[[a + 1, b + 1] for a, b in sorted(edges)]}"]
    lines += [f"[[followers]]\npos_m = {p}" for p in pos]
    for _ in range(3):
        obs = sorted({int(x) + 1 for x in rng.choice(n, size=2)})
        lines.append(f'[[targets]]\npos_m = [0.0, 0.0]\nprofile = "constant"\nobserved_by = {obs}')
    return parse_scenario("\n".join(lines))


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(3, 10),
    extra=st.lists(st.tuples(st.integers(0, 9), st.integers(0, 9)), max_size=6),
    absent=st.sets(st.integers(0, 9), max_size=8),
    seed=st.integers(0, 100),
    policy=st.sampled_from(["scale", "keep"]),
)
def test_any_member_set_forms_one_connected_ring(
    n: int, extra: list[tuple[int, int]], absent: set[int], seed: int, policy: str
) -> None:
    s = random_graph_scenario(n, extra, seed)
    s = keep(s) if policy == "keep" else s
    members = [i for i in range(n) if i not in absent]
    if not members:
        return
    form = membership(s, members)
    assert connected(form.members, form.edges)
    assert all(a in form.members and b in form.members for a, b in form.edges)
    i, seen = form.members[0], []
    for _ in form.members:  # the successor map is one cycle over the members
        seen.append(i)
        i = form.successor[i]
    assert i == form.members[0] and sorted(seen) == list(form.members)
    assert sum(form.angles_rad.values()) == pytest.approx(2 * math.pi)
    assert all(obs and set(obs) <= set(form.members) for obs in form.observers)
    w = form.weights()
    np.testing.assert_allclose(w.sum(axis=0), len(form.members) / s.m)  # mean p~ = LAP
    assert not w[[j for j in range(n) if j not in form.members]].any()
    assert membership(s, list(reversed(members))) == form  # order of the input is irrelevant


def test_phases_and_time_to_reform_from_a_synthetic_series() -> None:
    from agents.analysis.timeseries import RunSeries
    from agents.membership.ring_accuracy import membership_phases, phase_report

    changes = [(-3.0, frozenset({0, 2})), (-2.0, frozenset({0, 1, 2, 3})),
               (10.0, frozenset({1, 2, 3})), (20.5, frozenset({0}))]
    phases = membership_phases(changes, 20.0)
    assert phases == [(0.0, 10.0, (0, 1, 2, 3)), (10.0, 20.0, (1, 2, 3))]
    t = np.arange(0.0, 20.0, 0.1)
    ring3 = membership(PAPER, [1, 2, 3])
    angles4 = np.cumsum([0.0, *PAPER.pattern.angles_rad[:3]])
    angles3 = {1: 0.0, 2: ring3.angles_rad[1], 3: ring3.angles_rad[1] + ring3.angles_rad[2]}
    pos = np.zeros((len(t), 4, 2))
    for k, tk in enumerate(t):
        for i in range(4):
            a = angles4[i] if tk < 10.0 or i == 0 else angles3[i]
            radius = 8.0 if tk < 10.0 or tk >= 13.0 or i == 0 else 9.0  # off for 3 s
            pos[k, i] = radius * np.array([np.cos(a), np.sin(a)])
    series = RunSeries(t, pos, np.zeros_like(pos), np.zeros_like(pos), np.zeros((len(t), 2, 2)))
    rows = phase_report(series, PAPER, phases)
    assert rows[0]["reform_s"] == 0.0 and rows[0]["radius_error_m"] < 1e-9
    assert rows[1]["members"] == [1, 2, 3]
    assert rows[1]["reform_s"] == pytest.approx(3.0, abs=0.11)
    assert rows[1]["angle_error"] < 1e-9
