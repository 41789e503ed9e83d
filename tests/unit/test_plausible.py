"""Per-neighbour plausibility (agents.follower.plausible): honest tracks pass, lies are
refused and counted per sender, and whatever a hostile neighbour sends, what is accepted
stays inside the documented bounds."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.follower.inputs import Latest
from agents.follower.plausible import GateLimits, Own, Plausibility, gate_limits, own_side
from agents.law.interface import Peer, Sample
from agents.loading.law_loader import make_law
from agents.loading.scenario_file import load_scenario
from agents.membership.follower_place import setup_for
from transport.messages import FollowerState, Header

pytestmark = pytest.mark.timeout(60)
LIM = GateLimits()
ODD = ("link_sums_m",)


def peer(r: complex, t: float, rate: complex = 0j, sum_m: complex | None = None) -> Peer:
    fields = {} if sum_m is None else {"link_sums_m": Sample(sum_m, 0j, t)}
    return Peer(Sample(r, rate, t), Sample(r, 0j, t), fields)


def gate(armed: bool = True, own_r: complex = 0j, centre: complex | None = 0j,
         own_sum: complex | None = None) -> Plausibility:
    g = Plausibility(0, LIM, ODD, hold_s=1.0)
    g.origin_s = 0.0
    sums = {} if own_sum is None else {"link_sums_m": {1: Sample(own_sum, 0j, 0.0)}}
    g.own = Own(Sample(own_r, 0j, 0.0), centre, sums, armed)
    return g


def test_a_continuous_estimate_passes_and_a_jump_is_refused_and_counted() -> None:
    g = gate()
    for k in range(50):  # 1 m/s, 50 Hz
        assert g.check(1, peer(0.02 * k + 0j, 0.02 * k, 1 + 0j), 0.02 * k) is None
    assert g.check(1, peer(1.0 + 25j, 1.0, 1 + 0j), 1.0) == "rate"
    assert g.check(1, peer(1.02 + 25j, 1.02, 1 + 0j), 1.02) == "rate"
    assert g.counters["implausible_f1"] == 2 and g.counters["implausible_rate"] == 2
    assert g.counters["implausible_first_ms_f1"] == 1000


def test_a_value_off_its_own_rate_is_refused_by_the_rate_check() -> None:
    g = gate(centre=None)
    # moving at 0.35 m/s where its rate says 1.1 m/s: no message is a replay
    refused = [g.check(1, peer(0.007 * k + 0j, 0.02 * k, 1.1 + 0j), 0.02 * k)
               for k in range(200)]
    first = refused.index("rate")
    assert 0.5 < 0.02 * first < 3.0 and all(w == "rate" for w in refused[first:])


@pytest.mark.parametrize("rate", [1.1 + 0j, 0.05j, 0.3 + 0.2j])
def test_a_frozen_value_whose_rate_says_it_moves_is_refused_within_three_messages(
        rate: complex) -> None:
    """A stale state under fresh stamps, whatever its rate: at 0.05 m/s the rate check
    alone would never see it (its leaky sum stays at rate * tau, under rate_m)."""
    g = gate(centre=None)
    for k in range(50):
        assert g.check(1, peer(rate * 0.02 * k, 0.02 * k, rate), 0.02 * k) is None
    frozen = rate * 0.02 * 49
    refused = [g.check(1, peer(frozen, 0.02 * k, rate), 0.02 * k) for k in range(50, 100)]
    assert refused[:2] == [None, None] and set(refused[2:]) == {"frozen"}
    assert g.counters["implausible_frozen"] == 48
    back = [g.check(1, peer(rate * 0.02 * k, 0.02 * k, rate), 0.02 * k)
            for k in range(100, 200)]
    assert back[-1] is None and back.index(None) * 0.02 < 1.0


def test_a_value_at_rest_resent_unchanged_is_honest() -> None:
    g = gate(centre=None)
    assert all(g.check(1, peer(5 + 0j, 0.02 * k), 0.02 * k) is None for k in range(200))


def test_a_liar_back_to_the_truth_is_taken_back_within_a_second() -> None:
    g = gate(centre=None)
    for k in range(50):
        assert g.check(1, peer(0j, 0.02 * k), 0.02 * k) is None
    # 25 m off for a second: the jump is refused (what stays off is agreement's to catch)
    lie = [g.check(1, peer(25 + 0j, 0.02 * k), 0.02 * k) for k in range(50, 100)]
    assert lie[0] == "rate"
    back = [g.check(1, peer(0j, 0.02 * k), 0.02 * k) for k in range(100, 200)]
    assert back[-1] is None and back.index(None) * 0.02 < 1.0


def settle(g: Plausibility, senders: tuple[int, ...] = (1,), r: complex = 0j,
           until_s: float = 10.0) -> float:
    """Honest messages from `senders` at `r` for `until_s`: their tracks are settled."""
    t = 0.0
    while t <= until_s:
        for j in senders:
            assert g.check(j, peer(r, t), t) is None
        t += 0.5
    return t - 0.5  # the last message's time


def test_agreement_once_armed_and_settled() -> None:
    assert gate(armed=False).check(1, peer(5.0 + 0j, 0.0), 0.0) is None
    assert gate().check(1, peer(5.0 + 0j, 0.0), 0.0) is None  # a fresh track converges first
    g = gate()
    t = settle(g)
    for k in range(400):  # drifting away at 1 m/s, its rate said: no jump, but disagreement
        t += 0.02
        why = g.check(1, peer(0.02 * k + 0j, t, 1 + 0j), t)
        if why is not None:
            break
    assert why == "agree" and 2.9 < 0.02 * k < 3.1


def test_a_follower_that_drifted_itself_still_takes_neighbours_that_agree() -> None:
    g = gate(own_r=6 + 0j, centre=0j)
    t = settle(g, (1, 2)) + 0.5
    assert g.check(1, peer(0j, t), t) is None
    g.own = Own(Sample(6 + 0j, 0j, t), 0j, {}, True)
    g._tracks.pop(2)  # with no other neighbour, our own estimate is the one reference
    assert g.check(1, peer(0j, t + 0.02), t + 0.02) == "agree"


def test_geometry_bounds_even_an_agreeing_neighbour() -> None:
    # agreeing with a follower that was itself dragged off is not enough: the targets it
    # sees bound where the centre can be
    assert gate(own_r=20 + 0j).check(1, peer(20.0 + 0j, 0.0), 0.0) == "geometry"


def test_link_sums_must_keep_cancelling() -> None:
    g = gate(own_sum=3 + 0j)
    assert g.check(1, peer(0j, 0.0, sum_m=-3 + 0j), 0.0) is None
    assert g.check(1, peer(0j, 0.02, sum_m=-3.1 + 0j), 0.02) is None
    assert g.check(1, peer(0j, 0.04, sum_m=1e5 + 0j), 0.04) == "rate"  # its rate said 0


def test_link_sums_set_far_off_stay_refused_once_their_rate_agrees() -> None:
    g = gate(own_sum=3 + 0j, centre=None)
    for k in range(50):
        assert g.check(1, peer(0j, 0.02 * k, sum_m=-3 + 0j), 0.02 * k) is None
    why = [g.check(1, peer(0j, 0.02 * k, sum_m=1e5 + 0j), 0.02 * k) for k in range(50, 500)]
    assert all(w is not None for w in why) and why[-1] == "link"


def test_link_sums_ramped_with_their_rate_said_still_do_not_cancel() -> None:
    g = gate(own_sum=3 + 0j)
    v = 5.0  # m/s, declared: the rate check passes, the link's two ends drift apart
    why = [g.check(1, Peer(Sample(0j, 0j, 0.02 * k), Sample(0j, 0j, 0.02 * k),
                           {"link_sums_m": Sample(-3 + v * 0.02 * k + 0j, v + 0j, 0.02 * k)}),
                   0.02 * k) for k in range(60)]
    assert "link" in why and "rate" not in why and why.index("link") * 0.02 * v < 6.0


def test_a_silence_is_not_a_lie_but_refusals_are_not_silence() -> None:
    g = gate(centre=None)
    assert g.check(1, peer(0j, 0.0), 0.0) is None
    assert g.check(1, peer(10 + 0j, 5.0), 5.0) is None  # back after a silence
    assert g.check(1, peer(900 + 0j, 15.0), 15.0) == "jump"  # but not from anywhere
    for k in range(1, 200):  # a liar refused for 4 s stays refused: it was never silent
        t = 15.0 + 0.02 * k
        assert g.check(1, peer((-1) ** k * 90 + 0j, t), t) in ("rate", "jump")


@settings(max_examples=300)
@given(st.lists(st.tuples(st.floats(-0.2, 0.2), st.floats(-0.2, 0.2)), min_size=5,
                max_size=60),
       st.floats(-math.pi, math.pi))
def test_honest_tracks_pass(wobble: list[tuple[float, float]], heading: float) -> None:
    """An estimate moving at the speed bound, with its rate off by up to 0.2 m/s, and a
    neighbour within the paper's eps of ours: never refused."""
    g = gate()
    v = 1.118 * complex(math.cos(heading), math.sin(heading))
    for k, (dx, dy) in enumerate(wobble):
        t = 0.02 * k
        g.own = Own(Sample(v * t, v, t), v * t, {}, True)
        assert g.check(1, peer(v * t + 0.05 + 0j, t, v + complex(dx, dy)), t) is None


finite = st.floats(-1e5, 1e5, allow_nan=False)


@settings(max_examples=300)
@given(st.lists(st.tuples(finite, finite, finite, finite, finite, st.floats(0.0, 0.9)),
                min_size=1, max_size=40))
def test_whatever_a_hostile_neighbour_sends_what_passes_is_bounded(
        msgs: list[tuple[float, float, float, float, float, float]]) -> None:
    """Armed and settled, an accepted estimate is within agree_m of ours and geometry_m of
    our targets' centre, however it was chosen; nothing raises."""
    g = gate(own_sum=0j)
    t = settle(g)
    for rx, ry, vx, vy, sx, dt in msgs:
        t += dt
        g.own = Own(Sample(0j, 0j, t), 0j, {"link_sums_m": {1: Sample(0j, 0j, t)}}, True)
        p = peer(complex(rx, ry), t, complex(vx, vy), complex(sx, 0.0))
        if g.check(1, p, t) is None:
            assert abs(p.r.at(t)) <= LIM.agree_m and abs(p.r.at(t)) <= LIM.geometry_m
    assert g.counters.total() >= 0


def test_latest_keeps_only_plausible_states() -> None:
    scen = load_scenario("paper")
    law = make_law(scen)
    latest = Latest(0, law.declared(), gate_limits(8.0))
    latest.gate.own = Own(Sample(0j, 0j, 0.0), 0j, {}, True)

    def state(r: tuple[float, float], t: float) -> FollowerState:
        return FollowerState(Header("follower-1", 1, t), 1, r, (0.0, 0.0), (8.0, 0.0),
                             (0.0, 0.0), (0.0, 0.0), t, {})

    latest.receive(state((0.1, 0.0), 1.0), 1.0)
    latest.receive(state((25.0, 0.0), 1.02), 1.02)
    assert latest.peers[1].r.value == 0.1 + 0j
    assert latest.gate.counters["implausible_f1"] == 1


def test_own_side_reads_the_published_link_sums() -> None:
    scen = load_scenario("paper")
    setup = setup_for(scen, 0)
    wire = {"link_sums_m": ((1, 2.0, 0.5), (3, -1.0, 0.0)),
            "link_rates_m_s": ((1, 0.1, 0.0), (3, 0.0, 0.0))}
    own = own_side(Sample(1j, 0j, 3.0), setup, {0: Sample(2 + 0j, 0j, 3.0)}, 3.0, wire,
                   make_law(scen).declared(), True)
    assert own.sums["link_sums_m"][1] == Sample(2 + 0.5j, 0.1 + 0j, 3.0)
    assert own.centre == 2 + 0j  # follower 1 sees target 1 alone, with weight 1
