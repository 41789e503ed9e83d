"""The networked follower's tick, driven in lock-step with one-tick-old peer data."""

from __future__ import annotations

import numpy as np
import pytest

from agents.core.metrics import compute_metrics, error_series
from agents.core.profiles import TargetMotion
from agents.core.timeseries import RunSeries
from agents.follower_logic import (
    FollowerMemory,
    FollowerSetup,
    PeerView,
    Sample,
    follower_tick,
    observe_target,
    ready,
)
from agents.scenario_file import load_scenario


def run_swarm(duration_s: float, rate_hz: float, delay_ticks: int = 1) -> RunSeries:
    """Every follower ticks on the peer states published `delay_ticks` ticks earlier."""
    s = load_scenario()
    dt = 1.0 / rate_hz
    setups = [FollowerSetup.from_scenario(s, i) for i in range(s.n)]
    memories = [FollowerMemory() for _ in range(s.n)]
    pos = np.asarray(s.follower_pos_m, float)
    vel = np.zeros_like(pos)
    motion = TargetMotion(s)
    history: list[dict[int, PeerView]] = []
    t_all, p_all, r_all, u_all, tg_all = [], [], [], [], []
    for k in range(int(duration_s * rate_hz) + 1):
        t = k * dt
        targets, _ = motion.state(t)
        published: dict[int, PeerView] = {}
        peers = history[-delay_ticks] if len(history) >= delay_ticks else {}
        r_now, dr_now, u_now = np.zeros_like(pos), np.zeros_like(pos), np.zeros_like(pos)
        for i, setup in enumerate(setups):
            for j in setup.observed:
                memories[i] = observe_target(memories[i], setup, j, targets[j], t)
            own = Sample(pos[i].copy(), vel[i].copy(), t)
            if ready(memories[i], setup, peers):
                memories[i], out = follower_tick(memories[i], setup, own, peers, t)
                r_now[i], dr_now[i], u_now[i] = out.r_m, out.dr_m_s, out.u_m_s
            else:
                r_now[i] = setup.weights @ targets
            published[i] = PeerView(
                Sample(r_now[i], dr_now[i], t), Sample(pos[i].copy(), vel[i], t)
            )
        history.append(published)
        t_all.append(t)
        p_all.append(pos.copy())
        r_all.append(r_now)
        u_all.append(u_now)
        tg_all.append(targets)
        vel = u_now
        pos = pos + dt * u_now
    return RunSeries(
        np.array(t_all), np.array(p_all), np.array(r_all), np.array(u_all), np.array(tg_all)
    )


@pytest.mark.timeout(60)
def test_networked_tick_forms_the_pattern_with_one_tick_of_delay() -> None:
    s = load_scenario()
    series = run_swarm(40.0, 50.0)
    errors = error_series(series, s.successor, np.asarray(s.pattern.angles_rad), 8.0)
    m = compute_metrics(series, errors, 20.0, 0.0999, 0.0199)
    # A full tick of delay on every link costs the paper's estimator ~5 cm of drift of
    # mean(r) during the first half second (flows of an edge no longer cancel); it stays
    # within the paper's bounds.
    assert m.estimator_error_m < 0.0999
    assert m.radius_error_m < 0.0999
    assert m.angle_error < 0.0199
    assert m.command_jump_m_s < 0.5
    assert m.settle_time_s is not None and m.settle_time_s < 15.0


def test_observations_out_of_order_are_ignored() -> None:
    s = load_scenario()
    setup = FollowerSetup.from_scenario(s, 0)
    mem = observe_target(FollowerMemory(), setup, 0, np.array([0.0, 0.0]), 1.0)
    mem = observe_target(mem, setup, 0, np.array([1.0, 0.0]), 2.0)
    np.testing.assert_allclose(mem.targets[0].rate, [1.0 * 1.0 / (1.1), 0.0])
    stale = observe_target(mem, setup, 0, np.array([9.0, 9.0]), 1.5)
    assert stale is mem
    unseen = observe_target(mem, setup, 1, np.array([5.0, 5.0]), 3.0)
    assert 1 not in unseen.targets  # follower 1 does not observe target 2


def test_not_ready_until_every_input_was_heard() -> None:
    s = load_scenario()
    setup = FollowerSetup.from_scenario(s, 0)
    mem = observe_target(FollowerMemory(), setup, 0, np.zeros(2), 0.0)
    view = PeerView(Sample(np.zeros(2), np.zeros(2), 0.0), Sample(np.ones(2), np.zeros(2), 0.0))
    assert not ready(mem, setup, {1: view})
    assert ready(mem, setup, {1: view, 3: view})


def test_stale_inputs_are_flagged() -> None:
    s = load_scenario()
    setup = FollowerSetup.from_scenario(s, 0)
    mem = observe_target(FollowerMemory(), setup, 0, np.array([0.0, 0.0]), 0.0)
    fresh = PeerView(
        Sample(np.zeros(2), np.zeros(2), 10.0), Sample(np.array([5.0, 5.0]), np.zeros(2), 10.0)
    )
    old = PeerView(
        Sample(np.zeros(2), np.zeros(2), 1.0), Sample(np.array([-5.0, 5.0]), np.zeros(2), 1.0)
    )
    own = Sample(np.array([8.0, 0.0]), np.zeros(2), 10.0)
    _, out = follower_tick(mem, setup, own, {1: fresh, 3: old}, 10.0)
    assert out.stale == ("target0", "follower3")
    assert np.all(np.isfinite(out.u_m_s))
