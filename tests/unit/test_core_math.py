"""The pure math of the estimator and the controller."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

from agents.core.controller import ControlGains, enclosing_control
from agents.core.controller_one import spacing_step_s
from agents.core.estimator import (
    EdgeOperators,
    EstimatorParams,
    consensus_rate,
    edge_fractions,
    estimator_rate,
    finite_difference_velocity,
    observation_weights,
)
from agents.core.geometry import (
    NO_CAP_PER_S,
    TWO_PI,
    included_angles,
    limited_sig,
    rotate_ccw,
    sig,
    wrap_2pi,
)
from agents.scenario.model import ccw_order, successor_is_cycle

RNG = np.random.default_rng(7)


def random_connected_adjacency(n: int, rng: np.random.Generator) -> np.ndarray:
    adj = np.zeros((n, n))
    order = rng.permutation(n)
    for a, b in itertools.pairwise(order):  # a spanning path keeps it connected
        adj[a, b] = adj[b, a] = 1.0
    extra = rng.random((n, n)) < 0.3
    extra = np.triu(extra, 1)
    adj = np.maximum(adj, extra + extra.T)
    return adj


def test_sig_is_odd_signed_power() -> None:
    x = np.array([-8.0, -1.0, 0.0, 0.5, 27.0])
    np.testing.assert_allclose(sig(x, 1.0 / 3.0), [-2.0, -1.0, 0.0, 0.5 ** (1 / 3), 3.0])
    np.testing.assert_allclose(sig(x, 3.0 / 7.0), np.sign(x) * np.abs(x) ** (3.0 / 7.0))
    np.testing.assert_allclose(sig(-x, 0.4), -sig(x, 0.4))


def test_limited_sig_caps_only_near_zero() -> None:
    x = np.array([-1e-6, 1e-6, 2.0, -2.0])
    plain = limited_sig(x, 1.0 / 3.0, 2.0, NO_CAP_PER_S)
    np.testing.assert_allclose(plain, 2.0 * sig(x, 1.0 / 3.0))
    capped = limited_sig(x, 1.0 / 3.0, 2.0, 10.0)
    np.testing.assert_allclose(capped[:2], 10.0 * x[:2])  # the cap binds at tiny errors
    np.testing.assert_allclose(capped[2:], plain[2:])  # and not at large ones
    assert np.all(np.sign(capped) == np.sign(x))


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


def test_ccw_successor_order_of_the_paper_case() -> None:
    followers = np.array([[10.0, -20.0], [18.0, 12.0], [4.0, 12.0], [-2.0, 16.0]])
    succ = ccw_order(followers, np.array([0.5, 0.5]))
    assert succ == (1, 2, 3, 0)
    assert successor_is_cycle(succ)
    assert not successor_is_cycle((1, 0, 3, 2))


@pytest.mark.parametrize("n", [2, 3, 5, 9, 16])
@pytest.mark.parametrize("step_fraction", [0.0, 0.5])
def test_estimator_flows_sum_to_zero_on_symmetric_graphs(n: int, step_fraction: float) -> None:
    adj = random_connected_adjacency(n, RNG)
    edges = EdgeOperators.from_adjacency(adj)
    params = EstimatorParams(k_e=6.0, alpha1=7.0 / 3.0, step_fraction=step_fraction)
    for _ in range(20):
        r = RNG.normal(size=(n, 2)) * RNG.choice([1e-4, 1.0, 100.0])
        rate = estimator_rate(r, edges, params, dt_s=0.02)
        np.testing.assert_allclose(rate.sum(axis=0), 0.0, atol=1e-9 * (1 + np.abs(rate).max()))


def test_local_consensus_matches_the_swarm_form() -> None:
    n = 6
    adj = random_connected_adjacency(n, RNG)
    edges = EdgeOperators.from_adjacency(adj)
    params = EstimatorParams(k_e=6.0, alpha1=7.0 / 3.0)
    r = RNG.normal(size=(n, 2))
    swarm = estimator_rate(r, edges, params, 0.02)
    for i in range(n):
        nbrs = np.nonzero(adj[i])[0]
        fractions = edge_fractions(adj, np.full(len(nbrs), i), nbrs)
        local = consensus_rate(r[i], r[nbrs], fractions, params, 0.02)
        np.testing.assert_allclose(local, swarm[i], rtol=1e-12, atol=1e-12)


def test_estimator_pulls_towards_neighbours() -> None:
    adj = np.array([[0.0, 1.0], [1.0, 0.0]])
    rate = estimator_rate(
        np.array([[0.0, 0.0], [1.0, -1.0]]),
        EdgeOperators.from_adjacency(adj),
        EstimatorParams(6.0, 7.0 / 3.0, 0.0),
        0.01,
    )
    np.testing.assert_allclose(rate[0], [6.0, -6.0])
    np.testing.assert_allclose(rate[1], [-6.0, 6.0])


def test_observation_weights_make_the_references_average_to_the_lap() -> None:
    obs = np.array([[1, 0, 0], [1, 1, 0], [0, 0, 1], [0, 1, 1], [0, 0, 0]], dtype=float)
    targets = RNG.normal(size=(3, 2))
    p_tilde = observation_weights(obs) @ targets
    np.testing.assert_allclose(p_tilde.mean(axis=0), targets.mean(axis=0))
    with pytest.raises(ValueError):
        observation_weights(np.array([[1.0, 0.0], [1.0, 0.0]]))


def test_finite_difference_velocity_ignores_stale_stamps() -> None:
    prev = np.array([0.0, 0.0])
    v = finite_difference_velocity(prev, 1.0, np.array([0.5, -1.0]), 1.5, np.zeros(2))
    np.testing.assert_allclose(v, [1.0, -2.0])
    kept = finite_difference_velocity(prev, 1.0, np.array([9.0, 9.0]), 1.0, v)
    np.testing.assert_allclose(kept, v)
    filtered = finite_difference_velocity(prev, 1.0, np.array([0.5, -1.0]), 1.5, np.zeros(2), 0.5)
    np.testing.assert_allclose(filtered, 0.5 * v)


GAINS = ControlGains(k_z=2.0, alpha2=3.0, k_d=2.0, alpha3=3.0, rho_d_m=8.0, w_d_rad_s=0.2)


def test_controller_on_the_pattern_only_rotates_and_follows() -> None:
    angles = np.array([0.4, 0.4, 0.4, 0.8]) * math.pi
    bearings = np.concatenate([[0.0], np.cumsum(angles[:-1])])
    center = np.array([3.0, -2.0])
    pos = center + 8.0 * np.stack([np.cos(bearings), np.sin(bearings)], axis=1)
    r = np.tile(center, (4, 1))
    v = np.array([[1.0, 0.5]] * 4)
    out = enclosing_control(pos, pos[[1, 2, 3, 0]], r, v, angles, GAINS, 0.02)
    np.testing.assert_allclose(out.z_m, 0.0, atol=1e-12)
    np.testing.assert_allclose(out.delta, 0.0, atol=1e-12)
    expected = v + 0.2 * 8.0 * rotate_ccw((pos - center) / 8.0)
    np.testing.assert_allclose(out.u_m_s, expected, atol=1e-9)


def test_controller_moves_radially_towards_the_circle() -> None:
    pos = np.array([[20.0, 0.0], [0.0, 2.0]])
    succ = pos[[1, 0]]
    out = enclosing_control(
        pos, succ, np.zeros((2, 2)), np.zeros((2, 2)), np.array([math.pi] * 2), GAINS, 0.02
    )
    assert out.u_m_s[0, 0] < 0.0  # outside the circle: inwards
    assert out.u_m_s[1, 1] > 0.0  # inside: outwards
    assert out.z_m[0] == pytest.approx(12.0)


@pytest.mark.parametrize("limit", [None, 0.05, 0.35])
def test_spacing_gain_times_successor_age_stays_under_its_limit(limit: float | None) -> None:
    """Near zero the spacing law is linear, gain g = step_fraction / (2 step); the step
    is stretched so that g x age <= limit (default step_fraction / 2), never shortened."""
    gains = dataclasses.replace(GAINS, step_fraction=0.25, spacing_gain_age=limit)
    bound = 0.5 * gains.step_fraction if limit is None else limit
    dt = 0.05
    for age in (0.0, 0.02, 0.05, 0.1, 0.2, 0.4, 3.0):
        step = spacing_step_s(gains, dt, age)
        gain = 0.5 * gains.step_fraction / step
        assert step >= dt and gain * age <= bound * (1 + 1e-12)
        if gain * age < bound * (1 - 1e-9):
            assert step == dt  # cut only where the product would exceed the limit
    # 0.35 keeps ring64's gain (2.5/s at 20 Hz) up to 0.14 s of age; the default halves
    # it at 0.1 s.
    assert spacing_step_s(dataclasses.replace(gains, spacing_gain_age=0.35), dt, 0.1) == dt
    assert spacing_step_s(dataclasses.replace(gains, spacing_gain_age=None), dt, 0.1) == 0.1
