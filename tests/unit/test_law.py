"""agents.law, the one source of the law, against the paper's equations in plain numpy.

tests/reference writes each equation as the paper states it, on (k, 2) arrays; the law
writes it once as scalar Python on complex plane vectors (what the followers run, and what
the lock-step engine compiles).  Random inputs over every branch: the cap and the power of
the step-limited law, step_fraction 0 (the paper's plain law), a successor's data age,
ranges down to the law's minimum, graphs of every shape.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.law.consensus import EstimatorParams, link_balance, link_flow
from agents.law.enclosing import TWO_PI, ControlGains, enclosing_control, spacing_step_s
from agents.law.paper_wiring import estimator_flow, gains_of
from agents.law.sig import NO_CAP_PER_S, limited_sig, rate_cap
from agents.law.target_velocity import finite_difference_velocity, lag_free_velocity
from agents.law.velocity_stage import fed_flow, lap_velocity
from agents.lockstep.kernel import _rates, law_vector
from tests.reference import law as ref

TOL = {"rtol": 1e-12, "atol": 1e-12}
real = st.floats(-1e3, 1e3, allow_nan=False)
small = st.one_of(real, st.floats(-1e-6, 1e-6, allow_nan=False))
vec = st.builds(complex, small, small)
alpha = st.sampled_from([1.0, 7.0 / 3.0, 3.0, 5.0])
fraction = st.sampled_from([0.0, 0.25, 0.5, 1.0])
dt = st.sampled_from([0.001, 0.005, 0.02, 0.1])
RNG = np.random.default_rng(7)


def plane(values: list[complex]) -> np.ndarray:
    return np.array([[v.real, v.imag] for v in values]).reshape(-1, 2)


def cx(row: np.ndarray) -> complex:
    return complex(row[0], row[1])


def random_connected_adjacency(n: int, rng: np.random.Generator) -> np.ndarray:
    adj = np.zeros((n, n))
    for a, b in itertools.pairwise(rng.permutation(n)):  # a spanning path: connected
        adj[a, b] = adj[b, a] = 1.0
    extra = np.triu(rng.random((n, n)) < 0.3, 1)
    return np.maximum(adj, extra + extra.T)


@given(x=small, a=alpha, gain=st.floats(0.01, 10.0), cap=st.floats(0.0, 1e12))
def test_limited_sig_is_the_capped_signed_power(x: float, a: float, gain: float,
                                                cap: float) -> None:
    expected = ref.limited_sig(np.array([x]), 1.0 / a, gain, cap)[0]
    assert limited_sig(x, 1.0 / a, gain, cap) == pytest.approx(expected, rel=1e-12, abs=0)
    assert limited_sig(-x, 1.0 / a, gain, cap) == -limited_sig(x, 1.0 / a, gain, cap)


def test_the_cap_binds_only_near_zero_and_vanishes_without_a_fraction() -> None:
    assert rate_cap(0.0, 0.02) == NO_CAP_PER_S and rate_cap(0.5, 0.02) == pytest.approx(25.0)
    for x in (-1e-6, 1e-6):  # the cap binds at tiny errors
        assert limited_sig(x, 1.0 / 3.0, 2.0, 10.0) == pytest.approx(10.0 * x)
    for x in (-2.0, 2.0):  # and not at large ones: the paper's law
        plain = 2.0 * ref.sig(np.array([x]), 1.0 / 3.0)[0]
        assert limited_sig(x, 1.0 / 3.0, 2.0, 10.0) == pytest.approx(plain)
        assert limited_sig(x, 1.0 / 3.0, 2.0, NO_CAP_PER_S) == pytest.approx(plain)


@given(r=vec, nbrs=st.lists(vec, max_size=5), a=alpha, f=fraction, step=dt,
       k_e=st.floats(0.1, 5.0), data=st.data())
def test_one_followers_flows_and_link_balance(r: complex, nbrs: list[complex], a: float,
                                              f: float, step: float, k_e: float,
                                              data: st.DataObject) -> None:
    fractions = data.draw(st.lists(st.floats(0.05, 1.0), min_size=len(nbrs), max_size=len(nbrs)))
    # Follower 0 and its neighbours 1..d: a star, its edge fractions the drawn ones.
    r_all = plane([r, *nbrs])
    n = len(nbrs)
    edges = ref.Edges(np.zeros(n, np.intp), np.arange(1, n + 1), np.array(fractions))
    expected = ref.edge_flows(r_all, edges, EstimatorParams(k_e, a, f), step)
    gains = gains_of(EstimatorParams(k_e, a, f), ControlGains(1.0, 1.0, 1.0, 1.0, 1.0, 1.0), step)
    got = [estimator_flow(r, r_j, gains, fr) for r_j, fr in zip(nbrs, fractions, strict=True)]
    np.testing.assert_allclose(plane(got), expected, **TOL)
    theirs = nbrs[::-1]
    np.testing.assert_allclose(plane([link_balance(got, theirs)])[0],
                               ref.link_balance(expected, plane(theirs)), **TOL)


@pytest.mark.parametrize("n", [2, 3, 5, 9, 16])
@pytest.mark.parametrize("order", [1, 2])
def test_the_swarms_rates_are_the_papers_and_the_flows_cancel(n: int, order: int) -> None:
    adj = random_connected_adjacency(n, RNG)
    edges = ref.Edges.of(adj)
    for step_fraction in (0.0, 0.5):
        params = EstimatorParams(6.0, 7.0 / 3.0, step_fraction, order)
        law = law_vector(params, ControlGains(1.0, 1.0, 1.0, 1.0, 1.0, 1.0), 0.02)
        for _ in range(10):
            scale = RNG.choice([1e-4, 1.0, 100.0])
            r, psi, p_rate = (RNG.normal(size=(n, 2)) * scale for _ in range(3))
            rate, vrate, rv = (np.zeros(n, np.complex128) for _ in range(3))
            # The lock-step kernel's rates, as plain Python: the law's functions per edge.
            _rates(r @ [1, 1j], psi @ [1, 1j], p_rate @ [1, 1j], law, edges.tails, edges.heads,
                   edges.fractions, rate, vrate, rv)
            phi_rate, psi_rate = ref.estimator_rates(r, psi, p_rate, edges, params, 0.02)
            np.testing.assert_allclose(plane(list(rate)), phi_rate, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(plane(list(vrate)), psi_rate, rtol=1e-12, atol=1e-12)
            flows = ref.consensus_rate(r, edges, params, 0.02)
            # Odd flows on a symmetric graph: sum(dPhi) = 0, mean(r) stays the LAP.
            assert abs(rate.sum() - (psi @ [1, 1j]).sum() * (order == 2)) <= 1e-9 * (
                1 + np.abs(flows).max())


def test_the_estimator_pulls_towards_neighbours() -> None:
    flow = link_flow(0j, complex(1.0, -1.0), 6.0, 3.0 / 7.0, NO_CAP_PER_S)
    assert flow == pytest.approx(complex(6.0, -6.0))
    assert link_flow(complex(1.0, -1.0), 0j, 6.0, 3.0 / 7.0, NO_CAP_PER_S) == -flow


@given(psi=vec, rate=vec, flow=vec)
def test_the_velocity_stage_estimates_the_laps_velocity_and_feeds_it(
        psi: complex, rate: complex, flow: complex) -> None:
    assert lap_velocity(psi, rate) == psi + rate  # rv_i = Psi_i + dp~_i/dt
    assert fed_flow(flow, psi) == flow + psi  # dPhi_i/dt = consensus + Psi_i


@settings(max_examples=300)
@given(pos=vec, succ=vec, r=vec, rate=vec, angle=st.floats(0.1, 6.2), f=fraction, step=dt,
       succ_age=st.sampled_from([0.0, 0.01, 0.3, 1e6]), a2=alpha, a3=alpha,
       gain_age=st.sampled_from([0.0, 0.05, 0.35]))
def test_enclosing_control_is_the_papers(pos: complex, succ: complex, r: complex, rate: complex,
                                         angle: float, f: float, step: float, succ_age: float,
                                         a2: float, a3: float, gain_age: float) -> None:
    gains = ControlGains(1.5, a2, 2.0, a3, 8.0, 0.2, f, gain_age)
    out = ref.enclosing_control(plane([pos]), plane([succ]), plane([r]), plane([rate]),
                                np.array([angle]), gains, step, succ_age)
    u, z, delta = enclosing_control(pos, succ, r, rate, angle, 1.5, 1.0 / a2, 2.0, 1.0 / a3,
                                    8.0, 0.2, f, gain_age, step, succ_age)
    assert z == pytest.approx(float(out.z_m[0]), rel=1e-12, abs=1e-12)
    # A bearing from r_i is undefined where a vehicle is at r_i (the complex product
    # underflows to 0 first), and the gap wraps: within an ulp of the wrap it may land at
    # either end.
    defined = abs(pos - r) * abs(succ - r) > 1e-300
    if defined and abs(abs(delta - out.delta[0]) * angle - TWO_PI) > 1e-6:
        assert delta == pytest.approx(float(out.delta[0]), rel=1e-9, abs=1e-9)
        np.testing.assert_allclose(plane([u])[0], out.u_m_s[0], rtol=1e-9, atol=1e-9)


def test_on_the_pattern_the_controller_only_rotates_and_follows() -> None:
    angles = np.array([0.4, 0.4, 0.4, 0.8]) * math.pi
    bearings = np.concatenate([[0.0], np.cumsum(angles[:-1])])
    center, v = complex(3.0, -2.0), complex(1.0, 0.5)
    pos = [center + 8.0 * complex(math.cos(b), math.sin(b)) for b in bearings]
    for i in range(4):
        u, z, delta = enclosing_control(pos[i], pos[(i + 1) % 4], center, v, angles[i], 2.0,
                                        1.0 / 3.0, 2.0, 1.0 / 3.0, 8.0, 0.2, 0.5, 0.0, 0.02, 0.0)
        assert z == pytest.approx(0.0, abs=1e-12) and delta == pytest.approx(0.0, abs=1e-12)
        assert u == pytest.approx(v + 0.2 * 1j * (pos[i] - center), abs=1e-9)


def test_the_controller_moves_radially_towards_the_circle() -> None:
    args = (0j, 0j, math.pi, 2.0, 1.0 / 3.0, 2.0, 1.0 / 3.0, 8.0, 0.2, 0.5, 0.0, 0.02, 0.0)
    outside, z, _ = enclosing_control(complex(20.0, 0.0), complex(0.0, 2.0), *args)
    inside, _, _ = enclosing_control(complex(0.0, 2.0), complex(20.0, 0.0), *args)
    assert outside.real < 0.0 and inside.imag > 0.0 and z == pytest.approx(12.0)


@pytest.mark.parametrize("limit", [0.0, 0.05, 0.35])
def test_spacing_gain_times_successor_age_stays_under_its_limit(limit: float) -> None:
    """Near zero the spacing law is linear, gain g = step_fraction / (2 step); the step
    is stretched so that g x age <= limit (0: step_fraction / 2), never shortened."""
    fraction, dt_s = 0.25, 0.05
    gains = ControlGains(2.0, 3.0, 2.0, 3.0, 8.0, 0.2, fraction, limit)
    bound = limit or 0.5 * fraction
    for age in (0.0, 0.02, 0.05, 0.1, 0.2, 0.4, 3.0):
        step = spacing_step_s(fraction, limit, dt_s, age)
        assert step == pytest.approx(ref.spacing_step_s(gains, dt_s, age), rel=1e-12)
        gain = 0.5 * fraction / step
        assert step >= dt_s and gain * age <= bound * (1 + 1e-12)
    # 0.35 keeps ring64's gain (2.5/s at 20 Hz) up to 0.14 s of age; the default halves
    # it at 0.1 s.
    assert spacing_step_s(fraction, 0.35, dt_s, 0.1) == dt_s
    assert spacing_step_s(fraction, 0.0, dt_s, 0.1) == 0.1


@settings(max_examples=50)
@given(seed=st.integers(0, 2**32 - 1), tau=st.sampled_from([0.05, 0.1]),
       accel_tau=st.sampled_from([0.2, 0.5]))
def test_the_target_velocity_filters_are_the_low_pass_and_its_lag(seed: int, tau: float,
                                                                 accel_tau: float) -> None:
    rng = np.random.default_rng(seed)
    stamps = np.cumsum(rng.uniform(0.01, 0.1, size=12))
    pos = rng.normal(size=(12, 2)) * 3.0
    plain, lag_free = ref.target_velocity(pos, stamps, tau, accel_tau)
    smooth = finite_difference_velocity(cx(pos[0]), stamps[0], cx(pos[1]), stamps[1], 0j)
    accel = 0j
    assert cx(plain[0]) == pytest.approx(smooth, rel=1e-12, abs=1e-12)
    for k in range(2, 12):
        vel, smooth, accel = lag_free_velocity(cx(pos[k - 1]), stamps[k - 1], cx(pos[k]),
                                               stamps[k], smooth, accel, tau, accel_tau)
        assert smooth == pytest.approx(cx(plain[k - 1]), rel=1e-9, abs=1e-9)
        assert vel == pytest.approx(cx(lag_free[k - 1]), rel=1e-9, abs=1e-9)


def test_a_stale_or_duplicate_stamp_keeps_the_velocity() -> None:
    v = finite_difference_velocity(0j, 1.0, complex(0.5, -1.0), 1.5, 0j)
    assert v == pytest.approx(complex(1.0, -2.0))
    assert finite_difference_velocity(0j, 1.0, complex(9.0, 9.0), 1.0, v) == v
    assert finite_difference_velocity(0j, 1.0, complex(0.5, -1.0), 1.5, 0j, 0.5) == 0.5 * v
