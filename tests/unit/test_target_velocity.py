"""A target's velocity from its observed positions: low-passed, without the low-pass's lag.

The follower differences a target's stamped positions and low-passes the result; a plain
low-pass trails an accelerating target (6 mm/s on paper_v2 at 20 Hz, which drove ring64's
halves apart, issue 15).  `lag_free_velocity` puts back what the lag costs.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.follower.inputs import Latest
from agents.law.target_velocity import finite_difference_velocity, lag_free_velocity
from agents.loading.scenario_file import load_scenario
from agents.membership.follower_place import setup_for

PERIOD_S = 0.05
TAU_S, ACCEL_TAU_S = 0.1, 0.5


def paper_v2_y(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    phase = t_s / 10.0 + math.pi / 4.0
    return 5.0 * (math.cos(math.pi / 4.0) - np.cos(phase)), 0.5 * np.sin(phase)


def track(pos_m: np.ndarray, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lag-free, plain low-passed) velocity after each observation from the third on."""
    smooth = plain = (pos_m[1] - pos_m[0]) / (t_s[1] - t_s[0])
    accel: complex = 0.0
    lag_free, plain_out = [], []
    for k in range(2, len(t_s)):
        vel, smooth, accel = lag_free_velocity(pos_m[k - 1], t_s[k - 1], pos_m[k], t_s[k],
                                               smooth, accel, TAU_S, ACCEL_TAU_S)
        plain = finite_difference_velocity(pos_m[k - 1], t_s[k - 1], pos_m[k], t_s[k], plain,
                                           TAU_S)
        lag_free.append(vel)
        plain_out.append(plain)
    return np.array(lag_free), np.array(plain_out)


@pytest.mark.timeout(30)
def test_a_constant_acceleration_is_tracked_exactly_where_the_low_pass_trails_it() -> None:
    t = np.arange(0.0, 10.0, PERIOD_S)
    accel = 0.3
    lag_free, plain = track(0.5 * accel * t**2, t)
    true = accel * t[2:]
    late = t[2:] > 8.0  # the acceleration's own low-pass has settled (tau 0.5 s)
    np.testing.assert_allclose(lag_free[late], true[late], atol=1e-5)
    np.testing.assert_allclose(true[late] - plain[late], accel * (TAU_S + 0.5 * PERIOD_S),
                               rtol=1e-6)


@pytest.mark.timeout(30)
def test_the_paper_v2_target_is_tracked_within_half_a_millimetre_per_second() -> None:
    t = np.arange(0.0, 120.0, PERIOD_S)
    pos, vel = paper_v2_y(t)
    lag_free, plain = track(pos, t)
    late = t[2:] > 20.0
    assert np.abs(lag_free - vel[2:])[late].max() < 5e-4
    assert np.abs(plain - vel[2:])[late].max() > 5e-3  # what it was


@pytest.mark.timeout(30)
def test_noise_costs_little_more_than_the_plain_low_pass() -> None:
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 200.0, PERIOD_S)
    pos, vel = paper_v2_y(t)
    lag_free, plain = track(pos + rng.normal(0.0, 0.01, len(t)), t)
    late = t[2:] > 20.0
    assert np.std((lag_free - vel[2:])[late]) < 1.4 * np.std((plain - vel[2:])[late])


@pytest.mark.timeout(30)
def test_a_start_from_rest_overshoots_little_and_briefly() -> None:
    t = np.arange(0.0, 4.0, PERIOD_S)
    pos = np.maximum(t - 0.5, 0.0)  # at rest, then 1 m/s
    lag_free, _ = track(pos, t)
    assert lag_free.max() < 1.15
    assert abs(lag_free[t[2:] > 3.0] - 1.0).max() < 0.01


@pytest.mark.timeout(60)
@settings(max_examples=60, deadline=None)
@given(
    gaps=st.lists(st.floats(0.001, 0.3), min_size=3, max_size=40),
    ys=st.lists(st.floats(-1e3, 1e3), min_size=40, max_size=40),
)
def test_the_followers_track_is_the_filter_on_any_stamps(gaps: list[float],
                                                         ys: list[float]) -> None:
    """What a follower keeps of a target (agents.follower.inputs) is the raw difference of
    its first two samples, then `lag_free_velocity` on each new one, on any stamps; a
    finite input stays finite."""
    setup = setup_for(load_scenario("paper"), 0)
    latest = Latest(0, {})
    stamps = list(np.cumsum([10.0, *gaps]))
    pos = [complex(y, -y) for y in ys[:len(stamps)]]
    for stamp, p in zip(stamps, pos, strict=False):
        latest.observe(setup, 0, p, stamp)
    got = latest.targets[0]
    n = len(got_stamps := stamps[:len(pos)])
    assert got.value == pos[n - 1] and got.stamp_s == got_stamps[-1]
    if n >= 3:
        want, _ = track(np.array(pos[:n]), np.array(got_stamps))
        assert got.rate == pytest.approx(complex(want[-1]), rel=1e-12, abs=1e-9)
    assert math.isfinite(got.rate.real) and math.isfinite(got.rate.imag)
