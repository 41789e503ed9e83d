"""The `lie` fault's lies (agents.follower.lie): false, but valid and in bounds, so that
every receiver's transport checks pass them and only plausibility can refuse them."""

from __future__ import annotations

import pytest

from agents.follower.lie import OFFSET_M, Liar, Published, begin_signal, end_signal
from agents.loading.law_loader import make_law
from agents.loading.scenario_file import load_scenario
from agents.scenario.faults import LIE_MODES
from transport.law_fields import reason

pytestmark = pytest.mark.timeout(30)
SPECS = make_law(load_scenario("paper")).declared()
TRUE = Published(1 + 2j, 0.5 + 0j, (3.0, 4.0), (0.1, 0.0),
                 {"link_sums_m": ((1, 2.0, 0.0), (3, -1.0, 1.0)),
                  "link_rates_m_s": ((1, 0.2, 0.0), (3, 0.0, 0.1))})


def told(mode: str | None, times: int = 1) -> list[Published]:
    liar = Liar(SPECS, seed=1)
    if mode is not None:
        liar.begin(mode)
    return [liar.apply(0.02 * k, TRUE) for k in range(times)]


def test_honest_until_told() -> None:
    assert told(None) == [TRUE]


def test_offset_moves_the_estimate_only() -> None:
    (out,) = told("offset")
    assert out.r == TRUE.r + OFFSET_M and out.fields == TRUE.fields and out.pos == TRUE.pos


def test_bound_puts_every_link_sum_at_the_bound_and_stays_valid() -> None:
    (out,) = told("bound")
    bound = SPECS["link_sums_m"].bound
    assert all(0.99 * bound < x <= bound for _, x, _ in out.fields["link_sums_m"])  # type: ignore[union-attr]
    assert all(x == 0.0 for _, x, _ in out.fields["link_rates_m_s"])  # type: ignore[union-attr]
    assert reason(out.fields, SPECS) is None


def test_walk_wanders_and_stale_freezes() -> None:
    walked = told("walk", 200)
    assert abs(walked[-1].r - TRUE.r) > 0.1 and reason(walked[-1].fields, SPECS) is None
    liar = Liar(SPECS)
    liar.begin("stale")
    first = liar.apply(0.0, TRUE)
    later = liar.apply(1.0, Published(9 + 9j, 0j, (0.0, 0.0), (0.0, 0.0), TRUE.fields))
    assert later == first == TRUE and liar.lies == 2
    liar.end()
    assert liar.apply(2.0, TRUE) is TRUE


def test_every_mode_has_its_signal() -> None:
    sigs = {begin_signal(m) for m in LIE_MODES} | {end_signal()}
    assert len(sigs) == len(LIE_MODES) + 1
