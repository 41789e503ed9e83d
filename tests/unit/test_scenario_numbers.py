"""A scenario's numbers written as text ("7/3", "0.25"): exactly what Fraction makes of
them, without importing fractions for a ratio of integers (agents.scenario.fields)."""

from __future__ import annotations

from fractions import Fraction

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agents.scenario.fields import exact_float, number
from errors import ScenarioError


@given(st.integers(-10**30, 10**30), st.integers(1, 10**30), st.sampled_from(["", " "]))
def test_a_ratio_of_integers_is_fractions_float(p: int, q: int, pad: str) -> None:
    text = f"{pad}{p}/{q}{pad}"
    assert exact_float(text) == float(Fraction(text))


@given(st.decimals(allow_nan=False, allow_infinity=False, places=6))
def test_a_decimal_is_fractions_float(value: object) -> None:
    assert exact_float(str(value)) == float(Fraction(str(value)))


@pytest.mark.parametrize("text", ["7/0", "7/-3", "7 / 3", "seven", "1/2/3", "",
                                  "1" + "0" * 400 + "/3", "1e400/1"])
def test_what_fraction_refuses_is_refused_with_the_field_named(text: str) -> None:
    with pytest.raises(ScenarioError, match=r"gains\.alpha1"):
        number({"alpha1": text}, "alpha1", "gains")


def test_the_shipped_exponent_reads_as_seven_thirds() -> None:
    assert number({"alpha1": "7/3"}, "alpha1", "gains") == 7 / 3
