"""The follower's numpy-free setup (agents.membership.follower_place) against the numpy reference,
and what a follower process leaves out of a scenario's checks (issue 15: lean processes)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.loading.scenario_file import load_scenario, parse_scenario, shipped_text
from agents.lockstep.estimator_weights import edge_fractions, observation_weights
from agents.membership.follower_place import setup_for
from agents.membership.ring import membership
from agents.scenario.model import ccw_order
from errors import InadmissibleError

SCENARIOS = {name: load_scenario(name) for name in ("paper", "ring16")}
PAPER_TEXT = shipped_text("paper")


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(sorted(SCENARIOS)), st.data())
def test_weights_and_edge_fractions_match_the_numpy_reference(name: str, data: st.DataObject,
                                                               ) -> None:
    s = SCENARIOS[name]
    members = data.draw(st.sets(st.integers(0, s.n - 1), min_size=1))
    form = membership(s, members)
    adjacency = form.adjacency()
    if members == set(range(s.n)):  # everyone: the paper's W from the observation matrix
        np.testing.assert_allclose(form.weights(), observation_weights(s.observation()))
    for i in members:
        setup = setup_for(s, i, members)
        nbrs = np.asarray(setup.neighbours, int)
        want = edge_fractions(adjacency, np.full(len(nbrs), i), nbrs)
        assert setup.nbr_fractions == pytest.approx(tuple(want), rel=0, abs=0)
        row = form.weights()[i]
        assert setup.observed == tuple(int(j) for j in np.nonzero(row)[0])
        assert setup.weights == tuple((j, float(row[j])) for j in setup.observed)
        assert setup.peers == tuple(sorted({*setup.neighbours, setup.successor}))


@given(st.lists(st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)), min_size=2,
                max_size=12), st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)))
def test_ccw_order_sorts_by_the_bearing_as_numpys_stable_argsort(
        points: list[tuple[float, float]], center: tuple[float, float]) -> None:
    d = np.asarray(points) - np.asarray(center)
    order = [int(k) for k in np.argsort(np.arctan2(d[:, 1], d[:, 0]), kind="stable")]
    succ = ccw_order(points, center)
    assert [succ[order[k]] for k in range(len(order))] == order[1:] + order[:1]


def test_a_follower_leaves_out_only_the_whole_run_spread_check() -> None:
    narrow = PAPER_TEXT.replace("rho_d_m = 8.0", "rho_d_m = 2.0")
    with pytest.raises(InadmissibleError, match=r"pattern\.rho_d_m"):
        parse_scenario(narrow)
    assert parse_scenario(narrow, whole_run=False).pattern.rho_d_m == 2.0
    broken = PAPER_TEXT.replace("[[1, 2], [2, 3], [3, 4], [4, 1]]", "[[1, 2], [3, 4]]")
    with pytest.raises(InadmissibleError, match=r"graph\.edges"):
        parse_scenario(broken, whole_run=False)
