"""The lock-step engine runs the law's one source: compiled, it is the same as interpreted,
and both are the paper's closed loop written plainly in numpy (tests/reference/lockstep)."""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

from agents.analysis.timeseries import RunSeries
from agents.law import consensus, enclosing, sig, velocity_stage
from agents.loading.scenario_file import load_scenario, parse_scenario
from agents.lockstep import kernel as lockstep_kernel
from agents.lockstep.engine import estimator_substeps, simulate_lockstep
from agents.scenario.model import Scenario
from tests.reference import lockstep as reference
from tests.unit.test_closed_loop import SIX

needs_numba = pytest.mark.skipif(not lockstep_kernel.HAVE_NUMBA, reason="numba not installed")


def _paper(fraction: float, est_fraction: float | None) -> Scenario:
    paper = load_scenario()
    gains = dataclasses.replace(paper.gains, step_fraction=fraction,
                                estimator_step_fraction=est_fraction)
    return dataclasses.replace(paper, gains=gains)


def _ring16_order2() -> Scenario:
    ring = load_scenario("ring16")
    return dataclasses.replace(ring, gains=dataclasses.replace(ring.gains, estimator_order=2))


CASES = {
    "paper": (lambda: _paper(0.5, None), 0.02, None),
    "paper plain Euler": (lambda: _paper(0.0, None), 0.02, None),
    "paper own estimator share": (lambda: _paper(0.3, 0.9), 0.02, None),
    "general graph": (lambda: parse_scenario(SIX), 0.02, None),
    "velocity stage, estimator substeps": (_ring16_order2, 0.02, 0.005),
}


def _assert_same(got: RunSeries, expected: RunSeries, atol: float) -> None:
    np.testing.assert_allclose(got.follower_pos_m, expected.follower_pos_m, rtol=0, atol=atol)
    np.testing.assert_allclose(got.estimate_m, expected.estimate_m, rtol=0, atol=atol)
    np.testing.assert_allclose(got.command_m_s, expected.command_m_s, rtol=0, atol=10 * atol)


@needs_numba
@pytest.mark.timeout(180)
@pytest.mark.parametrize("case", CASES)
def test_compiled_is_the_same_law_as_interpreted(case: str) -> None:
    make, dt_s, est_dt_s = CASES[case]
    scenario = make()
    compiled = simulate_lockstep(scenario, dt_s, 2.0, engine="numba", estimator_dt_s=est_dt_s)
    python = simulate_lockstep(scenario, dt_s, 2.0, engine="python", estimator_dt_s=est_dt_s)
    _assert_same(compiled, python, 1e-12)


@pytest.mark.timeout(180)
@pytest.mark.parametrize("case", CASES)
def test_the_engine_is_the_papers_closed_loop(case: str) -> None:
    make, dt_s, est_dt_s = CASES[case]
    scenario = make()
    got = simulate_lockstep(scenario, dt_s, 10.0, estimator_dt_s=est_dt_s)
    expected = reference.simulate(scenario, dt_s, 10.0, estimator_substeps(dt_s, est_dt_s))
    _assert_same(got, expected, 1e-9)


@pytest.mark.timeout(120)
def test_the_engine_is_the_papers_closed_loop_at_1_ms() -> None:
    got = simulate_lockstep(load_scenario(), 0.001, 5.0)
    _assert_same(got, reference.simulate(load_scenario(), 0.001, 5.0), 1e-9)


def test_unknown_engine_is_refused() -> None:
    with pytest.raises(ValueError, match="engine"):
        simulate_lockstep(load_scenario(), 0.1, 1.0, engine="gpu")


@needs_numba
def test_the_compiled_loops_disk_cache_is_keyed_on_every_law_source() -> None:
    """numba would key it on the loop's own file: a changed law would run from the cache."""
    equations = {inspect.getfile(module) for module in (sig, consensus, velocity_stage,
                                                         enclosing)}
    used = {inspect.getfile(fn) for fn in lockstep_kernel._LAW}
    assert equations <= used  # every law file the loop is built from is in the digest
    stamp = lockstep_kernel.compiled_steps()._cache._cache_file._source_stamp
    assert stamp[1] == lockstep_kernel.sources_digest()


def test_without_numba_auto_runs_the_law_interpreted(monkeypatch: pytest.MonkeyPatch) -> None:
    def no_numba() -> None:
        raise AssertionError("compiled without numba")

    monkeypatch.setattr(lockstep_kernel, "HAVE_NUMBA", False)
    monkeypatch.setattr(lockstep_kernel, "compiled_steps", no_numba)
    auto = simulate_lockstep(load_scenario(), 0.02, 1.0)
    _assert_same(auto, simulate_lockstep(load_scenario(), 0.02, 1.0, engine="python"), 0.0)
