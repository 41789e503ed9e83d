"""The core's scalar twins (complex plane vectors, Python floats) are its numpy laws, to 1e-9.

The paper's law (agents.law.paper) calls them once per follower and step; the lock-step
engines call the vectorised ones.  Random inputs over every branch: the cap
and the power of the step-limited law, step_fraction 0 (the paper's plain law), a missing
successor's age, ranges down to the law's minimum.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.core.controller import ControlGains, enclosing_control, enclosing_control_one
from agents.core.estimator import (
    EstimatorParams,
    consensus_flows,
    consensus_flows_c,
    finite_difference_velocity,
    link_balance,
    link_balance_c,
)
from agents.core.geometry import limited_sig, limited_sig_one

TOL = {"rtol": 1e-12, "atol": 1e-12}
real = st.floats(-1e3, 1e3, allow_nan=False)
small = st.one_of(real, st.floats(-1e-6, 1e-6, allow_nan=False))
vec = st.builds(complex, small, small)
alpha = st.sampled_from([1.0, 7.0 / 3.0, 3.0, 5.0])
fraction = st.sampled_from([0.0, 0.25, 0.5, 1.0])
dt = st.sampled_from([0.001, 0.005, 0.02, 0.1])


def plane(values: list[complex]) -> np.ndarray:
    return np.array([[v.real, v.imag] for v in values]).reshape(-1, 2)


@given(x=small, a=alpha, gain=st.floats(0.01, 10.0), cap=st.floats(0.0, 1e12))
def test_limited_sig_one(x: float, a: float, gain: float, cap: float) -> None:
    expected = limited_sig(np.array([x]), 1.0 / a, gain, cap)[0]
    assert limited_sig_one(x, 1.0 / a, gain, cap) == pytest.approx(expected, rel=1e-12, abs=0)


@given(r=vec, nbrs=st.lists(vec, max_size=5), a=alpha, f=fraction, step=dt,
       k_e=st.floats(0.1, 5.0), data=st.data())
def test_consensus_flows_and_link_balance(r: complex, nbrs: list[complex], a: float, f: float,
                                          step: float, k_e: float, data: st.DataObject) -> None:
    fractions = data.draw(st.lists(st.floats(0.05, 1.0), min_size=len(nbrs), max_size=len(nbrs)))
    params = EstimatorParams(k_e, a, f)
    expected = consensus_flows(np.array([r.real, r.imag]), plane(nbrs), np.array(fractions),
                               params, step)
    got = consensus_flows_c(r, nbrs, fractions, params, step)
    np.testing.assert_allclose(plane(got), expected, **TOL)
    theirs = nbrs[::-1]
    np.testing.assert_allclose(plane([link_balance_c(got, theirs)])[0],
                               link_balance(expected, plane(theirs)), **TOL)


@settings(max_examples=300)
@given(pos=vec, succ=vec, r=vec, rate=vec, angle=st.floats(0.1, 6.2), f=fraction, step=dt,
       succ_age=st.sampled_from([0.0, 0.01, 0.3, 1e6]), a2=alpha, a3=alpha,
       gain_age=st.sampled_from([None, 0.05, 0.35]))
def test_enclosing_control_one(pos: complex, succ: complex, r: complex, rate: complex,
                               angle: float, f: float, step: float, succ_age: float,
                               a2: float, a3: float, gain_age: float | None) -> None:
    gains = ControlGains(1.5, a2, 2.0, a3, 8.0, 0.2, f, gain_age)
    out = enclosing_control(plane([pos]), plane([succ]), plane([r]), plane([rate]),
                            np.array([angle]), gains, step, succ_age)
    u, z, delta = enclosing_control_one(pos, succ, r, rate, angle, gains, step, succ_age)
    assert z == pytest.approx(float(out.z_m[0]), rel=1e-12, abs=1e-12)
    # delta wraps at 2 pi: a bearing within an ulp of zero may land at either end.
    if abs(abs(delta - out.delta[0]) * angle - 2 * np.pi) > 1e-6:
        assert delta == pytest.approx(float(out.delta[0]), rel=1e-9, abs=1e-9)
        np.testing.assert_allclose(plane([u])[0], out.u_m_s[0], rtol=1e-9, atol=1e-9)


@given(prev=vec, pos=vec, vel=vec, gap=st.floats(-0.1, 1.0), tau=st.sampled_from([0.0, 0.1]))
def test_velocity(prev: complex, pos: complex, vel: complex, gap: float, tau: float) -> None:
    got = finite_difference_velocity(prev, 1.0, pos, 1.0 + gap, vel, tau)
    expected = finite_difference_velocity(plane([prev])[0], 1.0, plane([pos])[0], 1.0 + gap,
                                          plane([vel])[0], tau)
    np.testing.assert_allclose(plane([got])[0], expected, rtol=1e-9, atol=1e-9)
