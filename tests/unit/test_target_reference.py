"""A target waits at its start point, at rest, and tracks its profile once started."""

from __future__ import annotations

import numpy as np
import pytest

from agents.loading.scenario_file import load_scenario
from agents.scenario.target_motion import TargetMotion
from agents.target import reference, tracking_command

pytestmark = pytest.mark.timeout(30)


def test_before_the_start_the_reference_is_the_start_point_at_rest() -> None:
    motion = TargetMotion(load_scenario("ring64"))
    start_pos, start_vel = motion.state(0.0)
    assert np.abs(start_vel).max() > 0.5  # the profile moves from t = 0: the case that mattered
    for j in range(len(start_pos)):
        pos, vel = reference(motion, j, None, 123.0)
        np.testing.assert_allclose(pos, start_pos[j])
        np.testing.assert_array_equal(vel, np.zeros(2))


def test_a_waiting_target_settles_on_its_start_point_not_ahead_of_it() -> None:
    motion = TargetMotion(load_scenario("paper"))
    pos = np.array([5.0, -3.0])
    dt_s = 0.02
    for _ in range(1000):  # 20 s of a vehicle that flies its setpoint
        ref_pos, ref_vel = reference(motion, 0, None, 0.0)
        pos = pos + dt_s * tracking_command(ref_pos, ref_vel, pos, 12.0)
    np.testing.assert_allclose(pos, motion.state(0.0)[0][0], atol=1e-3)


def test_after_the_start_the_reference_is_the_profile_at_the_time_since_the_start() -> None:
    motion = TargetMotion(load_scenario("paper"))
    for t_s in (0.0, 0.5, 17.0):
        want_pos, want_vel = motion.state(t_s)
        for j in range(len(want_pos)):
            pos, vel = reference(motion, j, 100.0, 100.0 + t_s)
            np.testing.assert_allclose(pos, want_pos[j])
            np.testing.assert_allclose(vel, want_vel[j])


def test_a_start_word_heard_early_does_not_set_the_target_off_before_its_start() -> None:
    motion = TargetMotion(load_scenario("paper"))
    start_pos = motion.state(0.0)[0]
    for now_s in (97.0, 99.0, 99.999):  # the launcher's word leads its start stamp
        pos, vel = reference(motion, 1, 100.0, now_s)
        np.testing.assert_allclose(pos, start_pos[1])
        np.testing.assert_array_equal(vel, np.zeros(2))


@pytest.mark.parametrize("case", ["paper", "ring64"])
def test_one_targets_state_is_its_share_of_all_targets_states(case: str) -> None:
    motion = TargetMotion(load_scenario(case))
    for t_s in (-1.0, 0.0, 0.37, 12.5, 150.0):
        all_pos, all_vel = motion.state(t_s)
        for j in range(len(all_pos)):
            pos, vel = motion.state_of(j, t_s)
            np.testing.assert_allclose(pos, all_pos[j], rtol=0, atol=1e-12)
            np.testing.assert_allclose(vel, all_vel[j], rtol=0, atol=1e-12)
