"""The numpy helpers: angles for the metrics (agents.analysis.geometry), the estimator's
weights (agents.lockstep.estimator_weights)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.analysis.geometry import as_complex, as_plane, included_angles, wrap_2pi
from agents.law.enclosing import TWO_PI
from agents.lockstep.estimator_weights import edge_fractions, observation_weights
from agents.scenario.model import ccw_order, successor_is_cycle

RNG = np.random.default_rng(7)


def test_wrap_2pi_range() -> None:
    wrapped = wrap_2pi(np.array([-0.1, 0.0, TWO_PI, 7.0, -7.0]))
    assert np.all((wrapped >= 0.0) & (wrapped < TWO_PI))
    np.testing.assert_allclose(wrapped[:2], [TWO_PI - 0.1, 0.0])
    assert wrapped[2] == pytest.approx(0.0, abs=1e-12)


def test_included_angles_of_a_square_and_their_sum() -> None:
    pos = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
    succ = np.array([1, 2, 3, 0])
    gaps = included_angles(pos, pos[succ], np.zeros(2))
    np.testing.assert_allclose(gaps, np.full(4, math.pi / 2))
    pts = RNG.normal(size=(7, 2)) * 5
    order = np.asarray(ccw_order(pts, np.zeros(2)))
    assert sum(included_angles(pts, pts[order], np.zeros(2))) == pytest.approx(TWO_PI)


def test_plane_rows_and_complex_views_round_trip() -> None:
    rows = RNG.normal(size=(3, 5, 2))
    view = as_complex(rows)
    assert view.shape == (3, 5) and view[1, 2] == complex(*rows[1, 2])
    np.testing.assert_array_equal(as_plane(view), rows)


def test_ccw_successor_order_of_the_paper_case() -> None:
    followers = np.array([[10.0, -20.0], [18.0, 12.0], [4.0, 12.0], [-2.0, 16.0]])
    succ = ccw_order(followers, np.array([0.5, 0.5]))
    assert succ == (1, 2, 3, 0)
    assert successor_is_cycle(succ)
    assert not successor_is_cycle((1, 0, 3, 2))


def test_observation_weights_make_the_references_average_to_the_lap() -> None:
    obs = np.array([[1, 0, 0], [1, 1, 0], [0, 0, 1], [0, 1, 1], [0, 0, 0]], dtype=float)
    targets = RNG.normal(size=(3, 2))
    p_tilde = observation_weights(obs) @ targets
    np.testing.assert_allclose(p_tilde.mean(axis=0), targets.mean(axis=0))
    with pytest.raises(ValueError):
        observation_weights(np.array([[1.0, 0.0], [1.0, 0.0]]))


def test_edge_fractions_are_one_over_the_larger_degree() -> None:
    adj = np.array([[0, 1, 1, 1], [1, 0, 0, 0], [1, 0, 0, 1], [1, 0, 1, 0]], dtype=float)
    tails, heads = np.nonzero(adj)
    # Degrees 3, 1, 2, 2: only the links 2 - 3 are between two followers of degree 2.
    expected = [1 / 2 if {i, j} == {2, 3} else 1 / 3 for i, j in zip(tails, heads, strict=True)]
    np.testing.assert_allclose(edge_fractions(adj, tails, heads), expected)
