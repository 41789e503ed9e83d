"""The paper's law (agents.law.paper) run through the interface as a follower runs it
(agents.follower: Latest, LawRunner), against the paper's equations written plainly in
numpy below, and its behaviour on missing, stale and paused inputs."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.analysis.metrics import compute_metrics, error_series
from agents.follower.inputs import Latest
from agents.follower.runner import LawRunner
from agents.law.interface import Output, Sample, reference
from agents.law.paper import PaperLaw, PaperState
from agents.loading.scenario_file import load_scenario
from agents.membership.follower_place import setup_for, stand_ins
from agents.scenario.model import Scenario
from tests.swarm_harness import run_swarm, with_estimator
from transport.messages import FollowerState, Header
from transport.network_schema import NetworkConfig

PAPER = load_scenario("paper")


# ---- the oracle: the paper's equations, plainly ---------------------------------------------
def limited_sig(x: np.ndarray, exponent: float, gain: float, cap: float) -> np.ndarray:
    """gain * sig(x)^exponent, its magnitude at most cap * |x| (a sampled step's share)."""
    return np.sign(x) * np.minimum(gain * np.abs(x) ** exponent, cap * np.abs(x))


def oracle_flows(r: np.ndarray, r_nbrs: list[np.ndarray], fractions: list[float],
                 s: Scenario, step_s: float) -> list[np.ndarray]:
    """k_e sig(r_j - r_i)^(1/alpha1) per link, each capped at its share of one step."""
    g = s.gains
    return [limited_sig(rj - r, 1.0 / g.alpha1, g.k_e, g.est_step_fraction / step_s * f)
            for rj, f in zip(r_nbrs, fractions, strict=True)]


def oracle_command(pos: np.ndarray, succ: np.ndarray, r: np.ndarray, dr: np.ndarray,
                   angle: float, s: Scenario, dt_s: float, succ_age_s: float) -> np.ndarray:
    """u = phi (-k_z sig(z)^(1/alpha2)) + phi_perp (k_d sig(delta)^(1/alpha3) + w_d rho)
    + dr/dt, with the gap wrapped to within half a turn of the desired angle."""
    g, p = s.gains, s.pattern
    rel = pos - r
    rho = max(np.hypot(*rel), 1e-9)  # at the centre: no bearing, no NaN
    radial = rel / rho
    perp = np.array([-radial[1], radial[0]])
    z = rho - p.rho_d_m
    gap = math.atan2(*(succ - r)[::-1]) - math.atan2(*rel[::-1])
    delta = ((gap - angle + math.pi) % (2 * math.pi) - math.pi) / angle
    cap = g.step_fraction / dt_s
    share = g.spacing_gain_age if g.spacing_gain_age is not None else 0.5 * g.step_fraction
    step_s = max(dt_s, succ_age_s * 0.5 * g.step_fraction / share)
    w_z = limited_sig(np.array(z), 1.0 / g.alpha2, g.k_z, cap)
    w_d = limited_sig(np.array(delta), 1.0 / g.alpha3, g.k_d,
                      0.5 * g.step_fraction / step_s * rho * angle) + p.w_d_rad_s * rho
    return np.asarray(-w_z * radial + w_d * perp + dr)


# ---- driving the law as the follower does ---------------------------------------------------
def xy(v: complex) -> np.ndarray:
    return np.array([v.real, v.imag])


def state_msg(j: int, r: complex, dr: complex, pos: complex, stamp: float,
              law: dict[str, object] | None = None) -> FollowerState:
    return FollowerState(Header(f"follower-{j}", 0, stamp), j, (r.real, r.imag),
                         (dr.real, dr.imag), (pos.real, pos.imag), (0.0, 0.0), (0.0, 0.0),
                         stamp, law or {})


class One:
    """Follower `index` of `scenario` with its inputs and its law, stepped by hand."""

    def __init__(self, scenario: Scenario = PAPER, index: int = 0) -> None:
        self.s = scenario
        self.runner = LawRunner(PaperLaw.from_params({}, scenario), setup_for(scenario, index))
        self.latest = Latest(index, self.runner.declared)
        self.setup = self.runner.setup

    def step(self, now_s: float, own: complex, command: bool = True) -> Output:
        peers = stand_ins(self.latest.peers, self.setup, self.runner.last_r, now_s)
        stepped = self.runner.step(now_s, command, Sample(own, 0j, now_s),
                                   self.latest.targets, peers)
        assert stepped is not None
        return stepped[0]

    @property
    def law(self) -> PaperState:
        state: PaperState = self.runner.state
        return state


vec = st.complex_numbers(max_magnitude=20.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=80, deadline=None)
@given(st.sampled_from(["paper", "robust"]), st.integers(0, 3), vec, vec, vec, vec, vec,
       st.floats(0.0, 0.3), st.floats(0.0, 0.3), st.floats(0.005, 0.05))
def test_first_steps_are_the_papers_equations(estimator: str, index: int, target: complex,
                                              r_a: complex, r_b: complex, own: complex,
                                              flow: complex, age_a: float, age_b: float,
                                              dt: float) -> None:
    """Two steps of a follower with random inputs: the estimate r = Phi + p~, the flows
    k_e sig(r_j - r_i)^(1/alpha1) (shrunk by the data's age), Phi integrated over dt (or the
    robust link balance) and the command, as the oracle computes them."""
    s = dataclasses.replace(PAPER, network=NetworkConfig(estimator))
    assert s.gains.lead_s == 0.0 and s.gains.estimator_order == 1
    one, now = One(s, index), 10.0
    setup = one.setup
    a, b = setup.neighbours
    robust = estimator == "robust"
    sums = {"link_sums_m": ((index, flow.real, flow.imag),),
            "link_rates_m_s": ((index, 0.1, -0.2),)} if robust else {}
    for j in setup.observed:
        one.latest.observe(setup, j, target + j, now)
    for j, r, age in ((a, r_a, age_a), (b, r_b, age_b)):
        one.latest.receive(state_msg(j, r, 0.1j, r + 5.0, now - age, sums), now)
    assume_heard = setup.successor in (a, b)
    assert assume_heard and one.latest.ready(setup)
    out = one.step(now, own)
    p_tilde = xy(reference(setup, one.latest.targets, now)[0])
    held = {j: xy(r + 0.1j * age) for j, r, age in ((a, r_a, age_a), (b, r_b, age_b))}
    step = setup.est_period_s
    fractions = [f * step / max(age, step)
                 for f, age in zip(setup.nbr_fractions, (age_a, age_b), strict=True)]
    theirs = [xy(flow + complex(0.1, -0.2) * age) for age in (age_a, age_b)]
    phi = -0.5 * sum(theirs) if robust else np.zeros(2)  # nothing integrated yet (dt = 0)
    r = phi + p_tilde
    flows = oracle_flows(r, [held[a], held[b]], fractions, s, step)
    phi_rate = 0.5 * sum(f - np.array([0.1, -0.2]) for f in flows) if robust else sum(flows)
    np.testing.assert_allclose(xy(out.r_m), r, atol=1e-9)
    np.testing.assert_allclose(xy(out.dr_m_s), phi_rate, atol=1e-9)  # targets still: p~' = 0
    succ = (a, b).index(setup.successor)
    succ_pos = xy((r_a, r_b)[succ] + 5.0)  # its position, at its stamp (no velocity)
    succ_age = min((age_a, age_b)[succ], setup.stale_s)
    u = oracle_command(xy(own), succ_pos, r, phi_rate, setup.angle_rad, s, setup.period_s,
                       succ_age)
    np.testing.assert_allclose(xy(out.u_m_s), u, atol=1e-9)
    later = one.step(now + dt, own, command=False)  # Phi integrates over dt
    if not robust:
        np.testing.assert_allclose(xy(one.law.phi_m), dt * phi_rate, atol=1e-9)
    else:
        sums_now = [dt * f for f in flows]
        theirs_now = [xy(flow + complex(0.1, -0.2) * (age + dt)) for age in (age_a, age_b)]
        np.testing.assert_allclose(xy(one.law.phi_m),
                                   0.5 * sum(m - t for m, t in zip(sums_now, theirs_now,
                                                                  strict=True)), atol=1e-9)
    assert later.u_m_s == 0j  # an estimator step commands nothing


@pytest.mark.timeout(60)
def test_networked_law_forms_the_pattern_with_one_tick_of_delay() -> None:
    series = run_swarm(PAPER, 40.0, 50.0)
    errors = error_series(series, PAPER.successor, np.asarray(PAPER.pattern.angles_rad), 8.0)
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
    one = One()
    one.latest.observe(one.setup, 0, 0j, 1.0)
    one.latest.observe(one.setup, 0, 1 + 0j, 2.0)
    assert one.latest.targets[0].rate == 1 + 0j  # the first velocity: raw
    one.latest.observe(one.setup, 0, 9 + 9j, 1.5)
    assert one.latest.targets[0] == Sample(1 + 0j, 1 + 0j, 2.0)
    one.latest.observe(one.setup, 1, 5 + 5j, 3.0)
    assert 1 not in one.latest.targets  # follower 1 does not observe target 2


def test_not_ready_until_every_input_was_heard() -> None:
    one = One()
    one.latest.observe(one.setup, 0, 0j, 0.0)
    one.latest.receive(state_msg(1, 0j, 0j, 1 + 1j, 0.0), 0.0)
    assert not one.latest.ready(one.setup)
    one.latest.receive(state_msg(3, 0j, 0j, 1 + 1j, 0.0), 0.0)
    assert one.latest.ready(one.setup)


def two_neighbours(stamp_3: float, succ_stamp: float = 10.0) -> One:
    """Follower 0 of the paper's case (robust): neighbours 1 and 3, 1 its successor."""
    one = One()
    assert one.setup.neighbours == (1, 3) and one.setup.successor == 1
    one.latest.observe(one.setup, 0, 0j, 10.0)
    one.latest.receive(state_msg(1, 0j, 0j, 5 + 5j, 10.0), 10.0)
    one.latest.peers[1] = one.latest.peers[1]._replace(pos=Sample(5 + 5j, 1 + 1j, succ_stamp))
    flows = {"link_sums_m": ((0, 0.4, 0.0),), "link_rates_m_s": ((0, 1.0, 0.0),)}
    one.latest.receive(state_msg(3, 3 + 0j, 1 + 0j, -5 + 5j, stamp_3, flows), 10.0)
    return one


def test_stale_inputs_are_counted() -> None:
    one = two_neighbours(stamp_3=1.0)
    peers = stand_ins(one.latest.peers, one.setup, None, 10.0)
    assert one.latest.stale(one.setup, peers, 10.0) == 1  # follower 3
    assert one.latest.stale(one.setup, peers, 11.0) == 3  # and target 0 and follower 1
    assert math.isfinite(abs(one.step(10.0, 8 + 0j).u_m_s))


def test_a_neighbour_older_than_the_limit_is_missing_not_extrapolated() -> None:
    one = two_neighbours(stamp_3=10.0 - 3.0)
    one.step(10.0, 8 + 0j)
    rates = one.law.link_rates_m_s
    assert rates is not None and rates[1] == 0j  # no flow on the missing link
    # Its link sum is carried at most hold_s (0.4 + 1.0 * 1 s), not 3 s on.
    assert one.law.phi_m == pytest.approx(0.5 * (0.0 - 1.4))
    fresh = two_neighbours(stamp_3=9.99)
    fresh.step(10.0, 8 + 0j)
    assert fresh.law.link_rates_m_s is not None and fresh.law.link_rates_m_s[1] != 0j


def test_a_missing_successor_leaves_only_radius_and_rotation() -> None:
    """A successor heard too long ago stands where it should be: the command is the one
    for a successor exactly there, and not the one for where it was last heard."""
    stale = two_neighbours(stamp_3=9.99, succ_stamp=5.0)
    u_stale, r = stale.step(10.0, 8 + 0j).u_m_s, stale.runner.last_r
    assert r is not None
    rotation = complex(math.cos(stale.setup.angle_rad), math.sin(stale.setup.angle_rad))
    placed = two_neighbours(stamp_3=9.99)
    placed.latest.peers[1] = placed.latest.peers[1]._replace(
        pos=Sample(r.value + (8 - r.value) * rotation, 0j, 10.0))
    assert placed.step(10.0, 8 + 0j).u_m_s == pytest.approx(u_stale, abs=1e-12)
    heard = two_neighbours(stamp_3=9.99, succ_stamp=9.9)  # heard in time: its bearing counts
    assert abs(heard.step(10.0, 8 + 0j).u_m_s - u_stale) > 0.01


def test_the_estimator_integrates_at_most_max_gap_after_a_pause() -> None:
    one = two_neighbours(stamp_3=9.99)
    one.step(10.0, 8 + 0j)
    sums, rates = one.law.link_sums_m, one.law.link_rates_m_s
    assert sums is not None and rates is not None
    for j, peer in list(one.latest.peers.items()):  # everything heard again, 5 s later
        fields = {k: v._replace(stamp_s=15.0) if isinstance(v, Sample) else v
                  for k, v in peer.fields.items()}
        one.latest.peers[j] = peer._replace(r=peer.r._replace(stamp_s=15.0),
                                            pos=peer.pos._replace(stamp_s=15.0), fields=fields)
    one.latest.observe(one.setup, 0, 0j, 15.0)
    one.step(15.0, 8 + 0j)
    assert one.law.link_sums_m == pytest.approx(
        [s + one.setup.max_gap_s * f for s, f in zip(sums, rates, strict=True)])


def test_targets_are_extrapolated_over_a_short_stall_and_held_after_a_long_one() -> None:
    one = One()
    one.latest.observe(one.setup, 0, 0j, 9.0)
    one.latest.observe(one.setup, 0, 0.1 + 0j, 10.0)
    rate = one.latest.targets[0].rate
    (_, w), = one.setup.weights
    p, v = reference(one.setup, one.latest.targets, 10.8)  # 0.8 s: bridged
    assert p == pytest.approx(w * (0.1 + 0.8 * rate)) and v == pytest.approx(w * rate)
    p, v = reference(one.setup, one.latest.targets, 13.0)  # 3 s: held at 1 s, no rate
    assert p == pytest.approx(w * (0.1 + 1.0 * rate)) and v == 0j


def test_parameters_and_fields_follow_the_scenario() -> None:
    """No [law] parameters of its own: its gains are [gains]; its fields its estimator's."""
    from errors import ScenarioError

    with pytest.raises(ScenarioError) as err:
        PaperLaw.from_params({"k_e": 3.0}, PAPER)
    assert err.value.field == "law.k_e"
    names = {est: [f.name for f in PaperLaw.from_params({}, with_estimator(PAPER, est)).fields]
             for est in ("paper", "robust", "robust2")}
    assert names == {"paper": [],  # its neighbours need nothing but r_j
                     "robust": ["link_sums_m", "link_rates_m_s"],
                     "robust2": ["link_sums_m", "link_rates_m_s", "rv_m_s", "vel_sums_m_s",
                                 "vel_rates_m_s2"]}
