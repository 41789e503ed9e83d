"""A start-up that fails on a saturated machine says so
(deploy.report.cpu_load.start_saturation_note):
64 followers on a slow 2-core machine starve their simulator, and every follower's error
then blames its vehicle."""

from __future__ import annotations

import os

import pytest

from deploy.report.cpu_load import start_saturation_note

pytestmark = pytest.mark.timeout(10)


def test_a_saturated_start_names_the_load_and_what_to_try() -> None:
    note = start_saturation_note((1_000, 10_000), (2_980, 12_000), 55.2, 67)
    assert note is not None
    assert "99 % busy" in note and "load 55" in note and "67 processes" in note
    assert f"{os.cpu_count() or 1} cores" in note
    assert "smaller swarm" in note and "rate_hz" in note
    assert "bench/bench_floor.py" in note  # the check of what this machine holds


@pytest.mark.parametrize("now", [(1_900, 12_000), None, (1_000, 10_000)])
def test_a_machine_with_room_or_unread_adds_nothing(now: tuple[int, int] | None) -> None:
    # 90 % busy; not read; no time passed
    assert start_saturation_note((100, 10_000), now, 3.0, 8) is None


def test_without_a_load_reading_the_note_still_comes() -> None:
    note = start_saturation_note((0, 0), (100, 100), None, 10)
    assert note is not None and "load" not in note and "100 % busy" in note
