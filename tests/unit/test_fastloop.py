"""The compiled lock-step twin agrees with the vectorised reference functions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agents.core import fastloop
from agents.core.lockstep import simulate_lockstep
from agents.scenario.file import load_scenario, parse_scenario
from tests.unit.test_closed_loop import SIX

pytestmark = pytest.mark.skipif(not fastloop.HAVE_NUMBA, reason="numba not installed")


@pytest.mark.timeout(120)
@pytest.mark.parametrize(("dt_s", "fraction", "est_fraction"),
                         [(0.001, 0.5, None), (0.02, 0.5, None), (0.02, 0.0, None),
                          (0.02, 0.3, 0.9)])
def test_numba_engine_matches_numpy_engine_on_the_paper_case(
        dt_s: float, fraction: float, est_fraction: float | None) -> None:
    paper = load_scenario()
    gains = dataclasses.replace(paper.gains, step_fraction=fraction,
                                estimator_step_fraction=est_fraction)
    scenario = dataclasses.replace(paper, gains=gains)
    ref = simulate_lockstep(scenario, dt_s, 10.0, engine="numpy")
    fast = simulate_lockstep(scenario, dt_s, 10.0, engine="numba")
    np.testing.assert_allclose(fast.follower_pos_m, ref.follower_pos_m, atol=1e-9)
    np.testing.assert_allclose(fast.estimate_m, ref.estimate_m, atol=1e-9)
    np.testing.assert_allclose(fast.command_m_s, ref.command_m_s, atol=1e-8)


@pytest.mark.timeout(120)
def test_numba_engine_matches_on_a_general_graph() -> None:
    scenario = parse_scenario(SIX)
    ref = simulate_lockstep(scenario, 0.02, 20.0, engine="numpy")
    fast = simulate_lockstep(scenario, 0.02, 20.0, engine="numba")
    np.testing.assert_allclose(fast.follower_pos_m, ref.follower_pos_m, atol=1e-9)
    np.testing.assert_allclose(fast.command_m_s, ref.command_m_s, atol=1e-8)


@pytest.mark.timeout(120)
@pytest.mark.parametrize("estimator_dt_s", [None, 0.005])
def test_numba_engine_matches_with_the_velocity_stage(estimator_dt_s: float | None) -> None:
    ring = load_scenario("ring16")
    scenario = dataclasses.replace(ring, gains=dataclasses.replace(ring.gains, estimator_order=2))
    ref = simulate_lockstep(scenario, 0.02, 10.0, engine="numpy", estimator_dt_s=estimator_dt_s)
    fast = simulate_lockstep(scenario, 0.02, 10.0, engine="numba", estimator_dt_s=estimator_dt_s)
    np.testing.assert_allclose(fast.follower_pos_m, ref.follower_pos_m, atol=1e-9)
    np.testing.assert_allclose(fast.estimate_m, ref.estimate_m, atol=1e-9)
    np.testing.assert_allclose(fast.command_m_s, ref.command_m_s, atol=1e-8)


def test_unknown_engine_is_refused() -> None:
    with pytest.raises(ValueError, match="engine"):
        simulate_lockstep(load_scenario(), 0.1, 1.0, engine="gpu")
