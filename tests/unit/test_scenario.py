"""Scenario files: the shipped paper case, and errors that name the bad field."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from agents.law.scenario_params import control_gains
from agents.loading.scenario_file import load_scenario, parse_scenario, shipped_text
from agents.scenario.target_motion import TargetMotion
from errors import ConfigError, InadmissibleError, ScenarioError
from tests.unit.test_closed_loop import load_scenario_text

PAPER = shipped_text("paper")


def test_paper_case_defaults() -> None:
    s = load_scenario()
    assert (s.n, s.m) == (4, 2)
    assert s.follower_pos_m[0] == (10.0, -20.0)
    assert s.successor == (1, 2, 3, 0)
    assert s.edges == ((0, 1), (0, 3), (1, 2), (2, 3))
    assert s.gains.alpha1 == pytest.approx(7.0 / 3.0)
    assert sum(s.pattern.angles_rad) == pytest.approx(2 * math.pi)
    assert s.targets[0].observed_by == (0, 1) and s.targets[1].observed_by == (2, 3)
    np.testing.assert_allclose(s.observation().sum(axis=0), [2, 2])


def edit(old: str, new: str) -> str:
    assert old in PAPER, old
    return PAPER.replace(old, new, 1)


@pytest.mark.parametrize(
    ("text", "field", "kind"),
    [
        (
            edit(
                "angles_deg = [72.0, 72.0, 72.0, 144.0]", "angles_deg = [72.0, 72.0, 72.0, 140.0]"
            ),
            "pattern.angles_deg",
            InadmissibleError,
        ),
        (
            edit("angles_deg = [72.0, 72.0, 72.0, 144.0]", "angles_deg = [72.0, 72.0, 216.0]"),
            "pattern.angles_deg",
            InadmissibleError,
        ),
        (edit("w_d_rad_s = 0.2", "w_d_rad_s = -0.2"), "pattern.w_d_rad_s", InadmissibleError),
        (edit("rho_d_m = 8.0", "rho_d_m = 2.0"), "pattern.rho_d_m", InadmissibleError),
        (edit("rho_d_m = 8.0", 'rho_d_m = "eight"'), "pattern.rho_d_m", ScenarioError),
        (
            edit("[[1, 2], [2, 3], [3, 4], [4, 1]]", "[[1, 2], [3, 4]]"),
            "graph.edges",
            InadmissibleError,
        ),
        (
            edit("[[1, 2], [2, 3], [3, 4], [4, 1]]", "[[1, 2], [2, 9]]"),
            "graph.edges[1]",
            ScenarioError,
        ),
        (
            edit("[[1, 2], [2, 3], [3, 4], [4, 1]]", "[[1, 1], [2, 3]]"),
            "graph.edges[0]",
            InadmissibleError,
        ),
        (
            edit("observed_by = [3, 4]", "observed_by = []"),
            "targets[1].observed_by",
            InadmissibleError,
        ),
        (edit('profile = "paper_v1"', 'profile = "teleport"'), "targets[0].profile", ScenarioError),
        (
            edit('profile = "paper_v1"', 'profile = "constant"\nvel_m_s = [2.0, 0.0]'),
            "targets[0].vel_m_s",
            InadmissibleError,
        ),
        (
            edit("beta_m_s = 1.118033988749895", "beta_m_s = 1.0"),
            "targets[1].profile",
            InadmissibleError,
        ),
        (edit("k_e = 6.0", "k_e = 0.0"), "gains.k_e", ScenarioError),
        (edit('alpha1 = "7/3"', 'alpha1 = "3/7"'), "gains.alpha1", InadmissibleError),
        (edit('alpha1 = "7/3"', 'alpha1 = "7/0"'), "gains.alpha1", ScenarioError),
        (edit("pos_m = [10.0, -20.0]", "pos_m = [10.0]"), "followers[0].pos_m", ScenarioError),
        (edit("order = [1, 2, 3, 4]", "order = [1, 2, 2, 4]"), "pattern.order", InadmissibleError),
        (
            edit("duration_s = 200.0", "duration_s = 200.0\nsteady_from_s = 300.0"),
            "run.steady_from_s",
            ScenarioError,
        ),
        (edit("beta_m_s = 1.118033988749895", ""), "beta_m_s", ScenarioError),
    ],
)
def test_bad_scenarios_name_their_field(text: str, field: str, kind: type[ConfigError]) -> None:
    with pytest.raises(kind) as info:
        parse_scenario(text)
    assert info.value.field == field
    assert field in str(info.value)


def test_broken_toml_and_missing_files_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="not valid TOML"):
        parse_scenario("[pattern\nrho_d_m = 8")
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "missing.toml")
    with pytest.raises(ScenarioError, match="no shipped scenario"):
        load_scenario("nope")


def test_profiles_velocity_is_the_derivative_of_position() -> None:
    text = PAPER.replace(
        'profile = "paper_v1"', 'profile = "random_walk"\nspeed_max_m_s = 1.0\nseed = 3'
    )
    text = text.replace(
        'profile = "paper_v2"', 'profile = "circle"\ncenter_m = [0.0, 0.0]\nomega_rad_s = 0.5'
    )
    text = text.replace("rho_d_m = 8.0", "rho_d_m = 30.0")
    s = parse_scenario(text)
    motion = TargetMotion(s)
    t = np.linspace(0.0, 150.0, 30001)
    pos, vel = motion.states(t)
    numeric = np.gradient(pos, t, axis=0)
    np.testing.assert_allclose(numeric[1:-1], vel[1:-1], atol=2e-3)
    assert np.linalg.norm(vel[:, 0], axis=1).max() <= 1.0 + 1e-9
    assert np.linalg.norm(vel[:, 1], axis=1) == pytest.approx(0.5 * math.sqrt(2.0))
    again, _ = TargetMotion(s).states(t)
    np.testing.assert_array_equal(pos, again)  # seeded: reproducible
    for k in (0, 4321, 30000):  # one target's state, as a target process asks it
        for j in range(2):
            one_pos, one_vel = motion.state_of(j, float(t[k]))
            np.testing.assert_allclose(one_pos, pos[k, j], rtol=0, atol=1e-12)
            np.testing.assert_allclose(one_vel, vel[k, j], rtol=0, atol=1e-12)


def test_paper_v2_matches_the_paper() -> None:
    motion = TargetMotion(load_scenario())
    pos, vel = motion.state(10.0)
    np.testing.assert_allclose(vel[1], [1.0, 0.5 * math.sin(1.0 + math.pi / 4)])
    np.testing.assert_allclose(pos[0], [10.0, 0.0])


def test_tick_groups_two_colour_the_ring() -> None:
    s = load_scenario()
    assert [s.tick_group(i) for i in range(s.n)] == [0, 1, 0, 1]
    for a, b in s.edges:
        assert s.tick_group(a) != s.tick_group(b)
    ring16 = load_scenario("ring16")
    assert all(ring16.tick_group(a) != ring16.tick_group(b) for a, b in ring16.edges)


@pytest.mark.parametrize("name", ["paper", "ring16", "ring32"])
def test_tick_phases_spread_and_keep_links_half_a_period_apart(name: str) -> None:
    s = load_scenario(name)
    phases = [s.tick_phase(i) for i in range(s.n)]
    assert all(0.0 <= p < 1.0 for p in phases)
    assert len(set(phases)) == s.n  # nobody wakes with anybody else
    for i in range(s.n):  # group 0 in the first half of the period, group 1 in the second
        assert (phases[i] >= 0.5) == (s.tick_group(i) == 1)
    for a, b in s.edges:  # each link's data is about half a period old both ways
        gap = (phases[b] - phases[a]) % 1.0
        assert 0.5 - 2.0 / s.n - 1e-9 <= gap <= 0.5 + 2.0 / s.n + 1e-9, (a, b, gap)


def test_ring64_talks_across_chords_and_its_neighbours_still_tick_apart() -> None:
    s = load_scenario("ring64")
    assert (s.n, s.run.rate_hz, len(s.edges)) == (64, 20.0, 96)
    chords = {tuple(sorted((i, (i + 31) % 64))) for i in range(0, 64, 2)}
    ring = {tuple(sorted((i, (i + 1) % 64))) for i in range(64)}
    assert {tuple(sorted(e)) for e in s.edges} == chords | ring
    phases = [s.tick_phase(i) for i in range(s.n)]
    assert len(set(phases)) == s.n
    assert all(sum(i in e for e in s.edges) == 3 for i in range(s.n))  # one chord each
    for a, b in s.edges:  # two-coloured: a neighbour's data is never from the same instant
        assert s.tick_group(a) != s.tick_group(b)
        # a chord's data may be almost a period old one way (fresh the other), never older
        assert 1.0 / s.n - 1e-9 <= (phases[b] - phases[a]) % 1.0 <= 1.0 - 1.0 / s.n + 1e-9
    for a, b in ring:
        assert abs((phases[b] - phases[a]) % 1.0 - 0.5) <= 2.0 / s.n + 1e-9


def test_estimator_step_fraction_is_its_own_share_and_checked() -> None:
    base = load_scenario_text()

    def with_share(value: str) -> str:
        return base.replace("alpha3 = 3.0", f"alpha3 = 3.0\nestimator_step_fraction = {value}")

    plain = parse_scenario(base)
    assert plain.gains.est_step_fraction == plain.gains.step_fraction == 0.5
    own = parse_scenario(with_share("0.9"))
    assert (own.gains.est_step_fraction, own.gains.step_fraction) == (0.9, 0.5)
    with pytest.raises(ScenarioError, match=r"gains\.estimator_step_fraction"):
        parse_scenario(with_share("1.5"))


def test_lead_is_zero_by_default_and_checked() -> None:
    base = load_scenario_text()

    def with_lead(value: str) -> str:
        return base.replace("alpha3 = 3.0", f"alpha3 = 3.0\nlead_s = {value}")

    assert parse_scenario(base).gains.lead_s == 0.0
    assert parse_scenario(with_lead("0.1")).gains.lead_s == 0.1
    for bad in ("-0.05", "2.0", "nan", '"soon"'):
        with pytest.raises(ScenarioError, match=r"gains\.lead_s"):
            parse_scenario(with_lead(bad))


def test_spacing_gain_age_is_off_by_default_positive_and_reaches_the_control_gains() -> None:
    base = load_scenario_text()

    def with_limit(value: str) -> str:
        return base.replace("alpha3 = 3.0", f"alpha3 = 3.0\nspacing_gain_age = {value}")

    assert parse_scenario(base).gains.spacing_gain_age is None
    scenario = parse_scenario(with_limit("0.35"))
    assert control_gains(scenario).spacing_gain_age == 0.35
    for bad in ("0", "-0.1", "nan", '"high"'):
        with pytest.raises(ScenarioError, match=r"gains\.spacing_gain_age"):
            parse_scenario(with_limit(bad))


def test_estimator_order_is_one_or_two_and_two_needs_the_robust_estimator() -> None:
    base = load_scenario_text()

    def with_order(value: str, extra: str = "") -> str:
        return base.replace("alpha3 = 3.0", f"alpha3 = 3.0\nestimator_order = {value}") + extra

    assert parse_scenario(base).gains.estimator_order == 1
    assert parse_scenario(with_order("2")).gains.estimator_order == 2
    assert load_scenario("ring16").gains.estimator_order == 2
    for bad in ("3", "1.5", "true", '"2"'):
        with pytest.raises(ScenarioError, match=r"gains\.estimator_order"):
            parse_scenario(with_order(bad))
    with pytest.raises(ScenarioError, match=r"gains\.estimator_order.*robust"):
        parse_scenario(with_order("2", '\n[network]\nestimator = "paper"\n'))


@pytest.mark.parametrize(("key", "default", "other", "bad"), [
    ("zenoh_runtime", "split", "one_thread", '"threads"'),
    ("agent_sched", "normal", "batch", '"fifo"'),
])
def test_network_choices_default_accept_the_other_and_name_a_bad_value(
        key: str, default: str, other: str, bad: str) -> None:
    base = load_scenario_text()
    assert getattr(parse_scenario(base).network, key) == default
    chosen = parse_scenario(base + f'\n[network]\n{key} = "{other}"\n')
    assert getattr(chosen.network, key) == other
    for value in (bad, "1", "true"):
        with pytest.raises(ScenarioError, match=rf"network\.{key}"):
            parse_scenario(base + f"\n[network]\n{key} = {value}\n")


def test_zenoh_lease_defaults_to_zenohs_takes_seconds_and_names_a_bad_value() -> None:
    base = load_scenario_text()
    assert parse_scenario(base).network.zenoh_lease_s is None  # Zenoh's own 10 s
    assert parse_scenario(base + "\n[network]\nzenoh_lease_s = 30\n").network.zenoh_lease_s \
        == 30.0
    for bad in ("0.5", "601", "nan", "true", '"30"'):
        with pytest.raises(ScenarioError, match=r"network\.zenoh_lease_s"):
            parse_scenario(base + f"\n[network]\nzenoh_lease_s = {bad}\n")
    assert load_scenario("ring64").network.zenoh_lease_s == 30.0


def test_journal_is_on_by_default_a_boolean_and_ring64_turns_it_off() -> None:
    base = load_scenario_text()
    assert "[run]\n" in base

    def with_journal(value: str) -> str:
        return base.replace("[run]\n", f"[run]\njournal = {value}\n", 1)

    assert parse_scenario(base).run.journal is True
    assert parse_scenario(with_journal("false")).run.journal is False
    for bad in ("0", '"no"', "1.0"):
        with pytest.raises(ScenarioError, match=r"run\.journal"):
            parse_scenario(with_journal(bad))
    assert load_scenario("ring64").run.journal is False
