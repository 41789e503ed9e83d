"""What every test shares: the order tests are handed out in, and a clean sys.path after each.

deploy/test.sh runs the suite side by side (pytest-xdist, `--dist loadgroup`): a worker is
handed the next test in collection order as it finishes one, so the real swarms, whose
length is real time, go first, longest first, and the short unit tests fill in behind them.
A test's timeout says how long it may take, and stands in for its length.

ENCLOSE_TEST_TIMEOUT_SCALE multiplies every test's timeout: deploy/test.sh runs the unit
tests at idle priority beside the timed tests (those marked `realtime`) and beside the
swarms (the others), where they take what those leave (beside swarms, a test that takes
4 s alone was seen to take over 60 s).  A timeout there still catches a hang; it is not a
measure of speed.

A real swarm starts only when the machine has room for it (tests/admission.py): the wait
comes before the test's timeout starts, and shows in the report's properties.
ENCLOSE_TEST_ADMISSION=0 starts every test at once.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator

import pytest
from hypothesis import settings
from pytest_timeout import get_env_settings

from tests.admission import Gate

pytest_plugins = ["tests.realtime_guard"]

# Hypothesis's 200-ms deadline per example measures the machine, not the code: beside the
# swarms an example may wait that long for the CPU.  Each test's timeout still catches a hang.
settings.register_profile("enclose", deadline=None)
settings.load_profile("enclose")

# Cores of normal-priority demand under which a test starts: a timed test wants about a
# core to itself on 2 cores; the other swarms fill the machine to about two thirds, which
# on a machine where a paper swarm takes ~0.45 of a core is four side by side.
SERIAL_ROOM, SWARM_ROOM = 0.3, 0.65


def _timeout_s(item: pytest.Item) -> float:
    """The item's timeout marker, else pytest-timeout's own default (--timeout,
    PYTEST_TIMEOUT or pyproject.toml's `timeout`, in its order); 0 is none."""
    marker = item.get_closest_marker("timeout")
    if marker is None or not marker.args:
        return float(get_env_settings(item.config).timeout or 0.0)
    return float(marker.args[0])


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    def key(item: pytest.Item) -> tuple[int, float]:
        if item.get_closest_marker("integration") is None:
            return (1, 0.0)  # unit tests after, in their own order
        return (0, -_timeout_s(item))

    items.sort(key=key)  # stable: equal keys keep the order they were collected in
    scale = _timeout_scale()
    if scale != 1.0:
        for item in items:
            # Put first, the closest marker is the one pytest-timeout reads.
            item.add_marker(pytest.mark.timeout(_timeout_s(item) * scale), append=False)


def _timeout_scale() -> float:
    text = os.environ.get("ENCLOSE_TEST_TIMEOUT_SCALE", "1")
    try:
        scale = float(text)
    except ValueError:
        raise pytest.UsageError(f"ENCLOSE_TEST_TIMEOUT_SCALE={text!r} is not a number") from None
    if not scale > 0:
        raise pytest.UsageError(f"ENCLOSE_TEST_TIMEOUT_SCALE={text!r} must be above 0")
    return scale


@pytest.hookimpl(tryfirst=True, hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item) -> Iterator[None]:
    """A real swarm waits for room before its protocol (and pytest-timeout's timer, which
    this wraps) starts."""
    if (item.get_closest_marker("integration") is not None
            and os.environ.get("ENCLOSE_TEST_ADMISSION", "1") != "0"):
        cores = (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                 else os.cpu_count() or 1)
        share = SERIAL_ROOM if item.get_closest_marker("serial") is not None else SWARM_ROOM
        waited_s, demand = Gate(threshold_cores=share * cores).admit()
        item.user_properties.append(("admission_wait_s", round(waited_s, 1)))
        item.user_properties.append(("admission_demand_cores", demand))
    yield


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    """How long the swarms waited for room: the run's length depends on it."""
    waits = [wait for reports in terminalreporter.stats.values() for r in reports
             if getattr(r, "when", None) == "call"
             and (wait := dict(getattr(r, "user_properties", ())).get("admission_wait_s"))
             is not None]
    if waits and max(waits) >= 1.0:
        terminalreporter.write_line(
            f"admission: {len(waits)} real swarms waited {sum(waits):.0f} s in all for room "
            f"on the machine, at most {max(waits):.0f} s (tests/admission.py)")
    not_judged = [w for w in terminalreporter.stats.get("warnings", [])
                  if "NotJudged" in str(getattr(w, "message", ""))]
    if not_judged:
        terminalreporter.write_line(
            f"real time: {len(not_judged)} accuracy checks not judged, their runs' machine did "
            "not keep real time (tests/integration/real_time.py; the warnings name them)",
            yellow=True, bold=True)
    # The excuses a pass took, counted always (zero included) where real swarms ran: an
    # idle machine must need none (a rerun is named above by -rR, a NotJudged by its warning).
    swarms = any(getattr(r, "when", None) == "call" and "integration" in r.keywords
                 for reports in terminalreporter.stats.values() for r in reports)
    if swarms:
        reruns = len(terminalreporter.stats.get("rerun", []))
        terminalreporter.write_line(
            f"excuses: {reruns} reruns, {len(not_judged)} accuracy checks not judged",
            yellow=bool(reruns or not_judged))


@pytest.fixture(autouse=True)
def _restore_sys_path(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """A law's folder put first on sys.path (agents.loading.law_loader) ends with its test: a later
    test of the same worker would otherwise hand it to the processes it starts, where a law
    file named as a module (a test's `json.py`) shadows the standard library's."""
    monkeypatch.setattr(sys, "path", list(sys.path))
    yield
