"""Gust windows on the timeline and the weather's command-line flags (issue 53)."""

from __future__ import annotations

import argparse

import pytest

from agents.loading.scenario_file import parse_scenario, shipped_text
from agents.scenario.faults import parse_fault_flag
from agents.shell.network_args import (
    NetworkOptions,
    add_network_arguments,
    apply_network_arguments,
    network_overrides,
)
from agents.weather.windows import WindSchedule, gust_std_at, window_strengths
from deploy.launch.launcher import gust_window_argv
from deploy.report.weather_report import weather_lines
from errors import ScenarioError

PAPER = shipped_text("paper")
WINDOW = '\n[[faults]]\nat_s = 10.0\naction = "wind"\nduration_s = 5.0\ngust_std_m_s = 2.0\n'


def test_a_wind_window_is_read_from_the_timeline() -> None:
    sc = parse_scenario(PAPER + WINDOW)
    (f,) = sc.faults
    assert (f.action, f.process, f.duration_s, f.gust_std_m_s) == ("wind", "sim", 5.0, 2.0)
    assert gust_std_at(sc.faults, 9.9, 0.5) == 0.5
    assert gust_std_at(sc.faults, 12.0, 0.5) == 2.0
    assert gust_std_at(sc.faults, 15.0, 0.5) == 0.5
    assert gust_window_argv(sc.faults) == ["--gust-window", "2.0"]


@pytest.mark.parametrize(("extra", "field"), [
    ("gust_std_m_s = -1.0", "gust_std_m_s"),
    ('gust_std_m_s = "x"', "gust_std_m_s"),
    ('target = "follower-1"\ngust_std_m_s = 1.0', "target"),
])
def test_a_bad_wind_window_is_refused_naming_the_field(extra: str, field: str) -> None:
    text = PAPER + '\n[[faults]]\nat_s = 1.0\naction = "wind"\nduration_s = 2.0\n' + extra
    with pytest.raises(ScenarioError, match=rf"faults\[0\]\.{field}"):
        parse_scenario(text)


def test_a_wind_window_needs_a_duration_and_a_kill_no_gust() -> None:
    with pytest.raises(ScenarioError, match=r"duration_s"):
        parse_scenario(PAPER + '\n[[faults]]\nat_s = 1.0\naction = "wind"\ngust_std_m_s = 1\n')
    with pytest.raises(ScenarioError, match=r"gust_std_m_s"):
        parse_scenario(PAPER + '\n[[faults]]\nat_s = 1.0\naction = "kill"\n'
                       'target = "follower-1"\ngust_std_m_s = 1\n')


def test_the_fault_flag_carries_the_windows_strength() -> None:
    f = parse_fault_flag("20:wind:sim:10:1.5", 4, 2)
    assert f is not None and f.gust_std_m_s == 1.5 and f.duration_s == 10.0
    assert window_strengths((f,)) == (1.5,)


def test_the_simulators_schedule_opens_windows_in_order() -> None:
    sched = WindSchedule((2.0, 3.0), 0.5)
    sched.begin()
    assert sched.std_m_s == 2.0
    sched.end()
    assert sched.std_m_s == 0.5
    sched.begin()
    sched.begin()  # more opened than there are: the last stays
    assert sched.std_m_s == 3.0


def flags(*argv: str) -> NetworkOptions:
    parser = argparse.ArgumentParser()
    add_network_arguments(parser)
    return NetworkOptions.from_namespace(parser.parse_args(list(argv)))


def test_the_weather_flags_reach_a_child_and_change_the_scenario() -> None:
    opts = flags("--wind", "2", "--gust", "0.5", "--gps-noise", "0.3")
    assert flags(*network_overrides(opts)) == opts
    sc = apply_network_arguments(parse_scenario(PAPER), opts)
    assert sc.wind is not None and sc.wind.mean_m_s == (2.0, 0.0)
    assert sc.wind.gust_std_m_s == 0.5 and sc.vehicle.gps_noise_std_m == 0.3
    assert flags("--wind", "1,-2").weather.wind == (1.0, -2.0)


def test_no_weather_flags_no_change() -> None:
    base = parse_scenario(PAPER)
    assert apply_network_arguments(base, flags()).wind is None
    assert "--wind" not in network_overrides(flags())


@pytest.mark.parametrize(("argv", "flag"), [(("--wind", "a,b"), "--wind"),
                                            (("--wind", "1,2,3"), "--wind"),
                                            (("--gust", "-1"), "--gust"),
                                            (("--gps-noise", "nan"), "--gps-noise")])
def test_bad_weather_flags_are_refused_naming_the_flag(argv: tuple[str, str], flag: str) -> None:
    with pytest.raises(ScenarioError, match=flag):
        flags(*argv)


def test_enclose_run_takes_the_weather_by_name() -> None:
    from enclose.api import launch_options

    opts = launch_options("paper", {"wind": (2, 1), "gust": 0.5, "gps_noise": 0.3})
    assert (opts.network.weather.wind, opts.network.weather.gust,
            opts.network.weather.gps_noise) == ((2.0, 1.0), 0.5, 0.3)
    assert launch_options("paper", {}).network.weather.given is False


def test_the_live_view_draws_the_mean_wind_as_an_arrow() -> None:
    from deploy.recording.scene import scene_update
    from transport.messages import Header, TruthSnapshot

    truth = TruthSnapshot(Header("sim-0", 1, 1.0), 1.0, ((0.0, 0.0, 10.0),), ((0.0, 0.0, 0.0),),
                          ((1.0, 1.0),), ((0.0, 0.0),))
    calm = scene_update(truth, {}, [], 10.0)
    windy = scene_update(truth, {}, [], 10.0, wind_m_s=(0.0, 2.0))
    # The bindings' messages are opaque: the arrow shows as its own entity in the bytes.
    assert b"wind" in windy.encode() and b"wind" not in calm.encode()


def test_a_simulator_without_windows_ignores_the_window_signals() -> None:
    import os
    import signal

    from agents.weather.windows import wind_begin_signal, wind_end_signal
    from sim_backend.swarm_sim import listen_for_wind

    before = [signal.getsignal(s) for s in (wind_begin_signal(), wind_end_signal())]
    try:
        listen_for_wind(None)
        os.kill(os.getpid(), wind_begin_signal())  # its default action would end the process
        sched = WindSchedule((2.0,), 0.0)
        listen_for_wind(sched)
        os.kill(os.getpid(), wind_begin_signal())
        assert sched.std_m_s == 2.0
        os.kill(os.getpid(), wind_end_signal())
        assert sched.std_m_s == 0.0
    finally:
        for s, h in zip((wind_begin_signal(), wind_end_signal()), before, strict=True):
            signal.signal(s, h)


def test_the_verdict_names_every_gust_window_the_launcher_opened() -> None:
    """A window given by --fault only is in no scenario: the verdict reads launch.json's."""
    launch = {"faults": [
        {"at_s": 5.0, "action": "wind", "process": "sim", "duration_s": 5.0,
         "gust_std_m_s": 3.0},
        {"at_s": 8.0, "action": "pause", "process": "follower-1", "duration_s": 2.0},
        {"at_s": "x", "action": "wind", "process": "sim", "duration_s": None,
         "gust_std_m_s": True},
    ]}
    lines = weather_lines({}, launch)
    assert lines == ("gust windows: 3 m/s from 5 s for 5 s, ? m/s from ? s for ? s",)
    assert weather_lines({}, {"faults": "garbage"}) == ()
