"""Weather (issue 53): the gust process, the wind on the airframes, GPS noise, the limited
sensor and the tables' validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.loading.scenario_file import parse_scenario, shipped_text
from agents.scenario.model import VehicleConfig
from agents.scenario.weather_tables import SensingConfig, WindConfig, parse_sensing, parse_wind
from agents.weather.gps import GpsNoise
from agents.weather.gusts import WindField, gust_step, steady_leak
from agents.weather.target_sensor import TargetSensor
from errors import ScenarioError
from sim_backend import kinematics
from sim_backend.kinematics import FleetCommand, FleetState, ModelParams

PAPER = shipped_text("paper")


def windy(extra: str) -> str:
    return PAPER + "\n" + extra + "\n"


# ---- the gust process --------------------------------------------------------------------
def test_gust_step_is_a_pure_function_of_its_inputs() -> None:
    state, draw = np.array([[0.3, -0.1]]), np.array([[1.0, -2.0]])
    a = gust_step(state, 0.02, 0.5, 2.0, draw)
    b = gust_step(state, 0.02, 0.5, 2.0, draw)
    assert np.array_equal(a, b)
    assert np.array_equal(state, [[0.3, -0.1]])  # inputs untouched


def test_a_seed_gives_the_same_gusts_and_another_seed_others() -> None:
    def series(seed: int) -> np.ndarray:
        field = WindField(WindConfig(gust_std_m_s=1.0, seed=seed), 3)
        return np.array([field.advance(0.02) for _ in range(50)])

    assert np.array_equal(series(4), series(4))
    assert not np.array_equal(series(4), series(5))


def test_the_gusts_stationary_std_is_the_configured_one_at_any_step() -> None:
    for dt in (0.001, 0.02, 0.5):
        field = WindField(WindConfig(gust_std_m_s=0.5, gust_tau_s=1.0, seed=1), 400)
        samples = np.array([field.advance(dt) for _ in range(200)])
        assert abs(samples.std() - 0.5) < 0.03, dt


def test_shared_gusts_are_one_gust_for_every_vehicle() -> None:
    field = WindField(WindConfig(mean_m_s=(2.0, 0.0), gust_std_m_s=1.0, per_vehicle=False), 4)
    v = field.advance(0.02)
    assert v.shape == (4, 2) and np.all(v == v[0])


def test_calm_air_is_the_mean_exactly() -> None:
    field = WindField(WindConfig(mean_m_s=(2.0, -1.0)), 2)
    assert np.array_equal(field.advance(0.1), [[2.0, -1.0], [2.0, -1.0]])


# ---- wind on the airframe ----------------------------------------------------------------
def hover_cmd(n: int) -> tuple[FleetState, FleetCommand]:
    s = FleetState.on_ground(np.zeros((n, 3)))
    s.pos_ned_m[:, 2] = -10.0
    c = FleetCommand.idle(n)
    c.motors_on[:] = True
    c.pos_axis[:, 2] = True
    c.pos_sp_ned_m[:, 2] = -10.0
    return s, c


def test_still_air_steps_bit_for_bit_as_before() -> None:
    s, c = hover_cmd(2)
    c.vel_sp_ned_m_s[:, 0] = 3.0
    p = ModelParams()
    a = kinematics.step(s, c, p, 0.02)
    b = kinematics.step(s, c, p, 0.02, None, 5.0)
    assert np.array_equal(a.pos_ned_m, b.pos_ned_m) and np.array_equal(a.vel_ned_m_s,
                                                                       b.vel_ned_m_s)


def test_a_steady_wind_leaves_the_velocity_loops_steady_error() -> None:
    s, c = hover_cmd(1)
    p, air = ModelParams(tau_s=0.05), np.array([[0.0, 4.0, 0.0]])  # 4 m/s from the west
    for _ in range(500):
        s = kinematics.step(s, c, p, 0.01, air, 1.0)
    assert s.vel_ned_m_s[0, 1] == pytest.approx(4.0 * steady_leak(1.0, 0.05, 0.01), rel=1e-3)
    assert steady_leak(1.0, 0.05, 1e-5) == pytest.approx(steady_leak(1.0, 0.05), rel=1e-3)
    assert s.pos_ned_m[0, 1] > 0.5  # the flown path drifts downwind
    assert s.pos_ned_m[0, 2] == pytest.approx(-10.0, abs=0.05)  # the position loop holds z


# ---- GPS noise ---------------------------------------------------------------------------
def test_gps_noise_has_its_std_and_its_bias_walks() -> None:
    gps = GpsNoise(VehicleConfig(gps_noise_std_m=0.3, gps_seed=2), 500)
    err = gps.advance(0.02)
    assert abs(err.std() - 0.3) < 0.03 and np.all(gps.bias == 0.0)
    walk = GpsNoise(VehicleConfig(gps_bias_walk_m_s=0.1, gps_seed=2), 500)
    for _ in range(100):
        walk.advance(0.01)
    assert abs(walk.bias.std() - 0.1) < 0.015  # 0.1 m/sqrt(s) over 1 s
    again = GpsNoise(VehicleConfig(gps_noise_std_m=0.3, gps_seed=2), 500)
    assert np.array_equal(again.advance(0.02), err)


def test_the_simulator_reports_noisy_positions_and_keeps_the_truth() -> None:
    from sim_backend.vehicle_weather import weather_of

    sc = parse_scenario(windy("").replace("[vehicle]", "[vehicle]\ngps_noise_std_m = 0.3")
                        if "[vehicle]" in PAPER else windy("[vehicle]\ngps_noise_std_m = 0.3"))
    weather = weather_of(sc, 3)
    assert weather is not None
    s, c = hover_cmd(3)
    s2 = weather.step(s, c, ModelParams(), 0.02)
    assert np.array_equal(s2.pos_ned_m, kinematics.step(s, c, ModelParams(), 0.02).pos_ned_m)
    reported = weather.reported_ned(s2.pos_ned_m)
    assert not np.array_equal(reported[:, :2], s2.pos_ned_m[:, :2])
    assert np.array_equal(reported[:, 2], s2.pos_ned_m[:, 2])


def test_no_weather_tables_no_weather() -> None:
    from sim_backend.vehicle_weather import weather_of

    assert weather_of(parse_scenario(PAPER), 3) is None


# ---- the limited sensor ------------------------------------------------------------------
def test_a_target_beyond_range_is_not_observed_and_counted() -> None:
    sensor = TargetSensor(SensingConfig(max_range_m=10.0))
    origin = np.zeros(2)
    assert sensor.observe(origin, origin, np.array([20.0, 0.0])) is None
    seen = sensor.observe(origin, origin, np.array([5.0, 0.0]))
    assert seen is not None and np.array_equal(seen, [5.0, 0.0])
    assert sensor.counters["sensing_out_of_range"] == 1


def test_detection_probability_misses_its_share() -> None:
    sensor = TargetSensor(SensingConfig(detect_prob=0.7, seed=3))
    z = np.zeros(2)
    seen = sum(sensor.observe(z, z, np.ones(2)) is not None for _ in range(2000))
    assert abs(seen / 2000 - 0.7) < 0.04
    assert sensor.counters["sensing_missed"] == 2000 - seen


def test_range_bearing_places_the_target_from_the_observers_reported_position() -> None:
    sensor = TargetSensor(SensingConfig(range_bearing=True))
    seen = sensor.observe(np.zeros(2), np.array([0.5, 0.0]), np.array([3.0, 4.0]))
    assert seen is not None and np.allclose(seen, [3.5, 4.0])


def test_latency_delivers_the_state_that_old() -> None:
    sensor = TargetSensor(SensingConfig(latency_s=0.1))
    out = [sensor.remember(k * 0.02, np.full((1, 2), k), np.zeros((1, 2))) for k in range(20)]
    assert out[19][0] == pytest.approx(0.28) and out[19][1][0, 0] == 14
    assert out[0][0] == 0.0  # younger than the latency: the oldest there is


# ---- validation --------------------------------------------------------------------------
@pytest.mark.parametrize(("table", "field"), [
    ("[wind]\ngust_std_m_s = -0.5", "wind.gust_std_m_s"),
    ("[wind]\ngust_tau_s = 0", "wind.gust_tau_s"),
    ("[wind]\nmean_m_s = [1]", "wind.mean_m_s"),
    ("[wind]\nper_vehicle = 1", "wind.per_vehicle"),
    ("[wind]\nseed = -1", "wind.seed"),
    ("[wind]\ngusty = true", "wind.gusty"),
    ("[sensing]\nmax_range_m = 0", "sensing.max_range_m"),
    ("[sensing]\ndetect_prob = 1.5", "sensing.detect_prob"),
    ("[sensing]\ndetect_prob = -0.1", "sensing.detect_prob"),
    ("[sensing]\nlatency_s = -1", "sensing.latency_s"),
    ("[sensing]\nnoise_std_m = nan", "sensing.noise_std_m"),
])
def test_bad_weather_is_refused_naming_the_field(table: str, field: str) -> None:
    with pytest.raises(ScenarioError, match=field.replace(".", r"\.")):
        parse_scenario(windy(table))


def test_the_vehicles_gps_fields_are_checked() -> None:
    with pytest.raises(ScenarioError, match=r"vehicle\.gps_noise_std_m"):
        parse_wind_free = windy("[vehicle]\ngps_noise_std_m = -0.3")
        parse_scenario(parse_wind_free)


def test_the_tables_read_back() -> None:
    sc = parse_scenario(windy("[wind]\nmean_m_s = [2, 0]\ngust_std_m_s = 0.5\n"
                              "[sensing]\nmax_range_m = 40\ndetect_prob = 0.9"))
    assert sc.wind == WindConfig(mean_m_s=(2.0, 0.0), gust_std_m_s=0.5)
    assert sc.sensing == SensingConfig(max_range_m=40.0, detect_prob=0.9)


HOSTILE = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=5),
                    st.lists(st.floats(), max_size=3))


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(st.sampled_from(["mean_m_s", "gust_std_m_s", "gust_tau_s", "per_vehicle",
                                        "seed", "drag_1_s", "other"]), HOSTILE))
def test_hostile_wind_tables_parse_or_are_refused_by_name(table: dict[str, object]) -> None:
    try:
        wind = parse_wind(table)
    except ScenarioError as exc:
        assert str(exc).startswith("wind.")
        return
    assert wind is not None and wind.gust_std_m_s >= 0.0 and wind.gust_tau_s > 0.0
    assert all(math.isfinite(v) for v in wind.mean_m_s)


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(st.sampled_from(["max_range_m", "detect_prob", "noise_std_m",
                                        "latency_s", "range_bearing", "seed"]), HOSTILE))
def test_hostile_sensing_tables_parse_or_are_refused_by_name(table: dict[str, object]) -> None:
    try:
        cfg = parse_sensing(table)
    except ScenarioError as exc:
        assert str(exc).startswith("sensing.")
        return
    assert cfg is not None and 0.0 <= cfg.detect_prob <= 1.0
    assert cfg.max_range_m is None or cfg.max_range_m > 0.0


# ---- lock-step ---------------------------------------------------------------------------
def test_lockstep_flies_in_the_same_wind_and_is_unchanged_without_it() -> None:
    from agents.lockstep.engine import simulate_lockstep

    calm = parse_scenario(PAPER)
    breeze = parse_scenario(windy("[wind]\nmean_m_s = [2, 0]\ngust_std_m_s = 0.5"))
    a = simulate_lockstep(calm, 0.02, 4.0, engine="python")
    b = simulate_lockstep(breeze, 0.02, 4.0, engine="python")
    c = simulate_lockstep(breeze, 0.02, 4.0, engine="python")
    assert np.array_equal(b.follower_pos_m, c.follower_pos_m)  # seeded
    drift = np.abs(b.follower_pos_m - a.follower_pos_m).max()
    assert 0.01 < drift < 2.0


def test_lockstep_laws_see_gps_noise_and_the_truth_is_judged() -> None:
    from agents.lockstep.engine import simulate_lockstep

    calm = simulate_lockstep(parse_scenario(PAPER), 0.02, 3.0, engine="python")
    noisy_sc = parse_scenario(windy("[vehicle]\ngps_noise_std_m = 0.3\ngps_seed = 1"))
    noisy = simulate_lockstep(noisy_sc, 0.02, 3.0, engine="python")
    assert np.array_equal(calm.follower_pos_m[:2], noisy.follower_pos_m[:2])  # same start
    assert not np.array_equal(calm.command_m_s, noisy.command_m_s)  # the law saw the noise


def test_lockstep_opens_a_gust_window_at_its_time() -> None:
    from agents.lockstep.engine import lockstep_wind

    sc = parse_scenario(windy('[wind]\ngust_std_m_s = 0.0\n[[faults]]\nat_s = 2.0\n'
                              'action = "wind"\nduration_s = 2.0\ngust_std_m_s = 3.0'))
    t = np.arange(301) * 0.02
    wind, _ = lockstep_wind(sc, t)
    assert np.all(wind[t < 2.0] == 0.0)  # calm until the window opens
    inside = np.abs(wind[(t > 2.5) & (t < 4.0)]).max()
    assert inside > 0.5
    assert np.abs(wind[-1]).max() < inside  # after it, the gusts die down at their tau


def test_lockstep_holds_what_its_sensor_missed() -> None:
    from agents.lockstep.engine import simulate_lockstep
    from agents.lockstep.held_observations import sensed_targets

    sc = parse_scenario(windy("[sensing]\ndetect_prob = 0.5\nseed = 2"))
    t = np.arange(101) * 0.02
    targets = np.cumsum(np.ones((101, sc.m, 2)), axis=0)  # every target moves every step
    held = sensed_targets(sc, t, targets)
    assert held is not None
    i, j = sc.targets[0].observed_by[0], 0
    moved = np.any(np.diff(held[:, i, j], axis=0) != 0.0, axis=1)
    assert 0.3 < moved.mean() < 0.7  # about half the steps bring a new observation
    assert sensed_targets(parse_scenario(PAPER), t, targets) is None
    run = simulate_lockstep(sc, 0.02, 3.0, engine="python")
    assert np.all(np.isfinite(run.estimate_m))


def test_lockstep_senses_within_range_from_where_each_follower_is() -> None:
    """A range no follower reaches draws as no range at all (the same draws, bit for bit);
    a short one keeps far targets unseen, and the run differs."""
    from agents.analysis.timeseries import RunSeries
    from agents.lockstep.engine import simulate_lockstep

    def run(extra: str) -> RunSeries:
        sc = parse_scenario(windy(f"[sensing]\ndetect_prob = 0.8\nseed = 3\n{extra}"))
        return simulate_lockstep(sc, 0.02, 3.0, engine="python")

    free, far, near = run(""), run("max_range_m = 1e6"), run("max_range_m = 12")
    assert np.array_equal(free.estimate_m, far.estimate_m)
    assert np.array_equal(free.follower_pos_m, far.follower_pos_m)
    assert not np.array_equal(free.estimate_m, near.estimate_m)
    assert np.all(np.isfinite(near.estimate_m))
