"""In-process lock-step integration of the paper's closed loop: no clock, no network.

Followers are single integrators p' = u (explicit Euler at dt).  Target positions
are sampled at every step; followers use only the targets they observe, and
estimate the targets' velocities by finite differences of those observations,
as the networked followers do.  The loop (agents.lockstep.kernel) runs the
followers' own law (agents.law): compiled by numba ("numba"; "auto" when it is
installed), or as plain Python ("python").
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

from agents.analysis.geometry import as_complex, as_plane
from agents.analysis.timeseries import RunSeries
from agents.law.scenario_params import control_gains, estimator_params
from agents.lockstep import kernel as lockstep_kernel
from agents.lockstep.estimator_weights import edge_fractions, observation_weights
from agents.scenario.model import Scenario
from agents.scenario.target_motion import TargetMotion

ProgressFn = Callable[[float], None]
ENGINES = ("auto", "python", "numba")
CHUNKS = 100


def simulate_lockstep(
    scenario: Scenario,
    dt_s: float,
    duration_s: float,
    progress: ProgressFn | None = None,
    engine: str = "auto",
    estimator_dt_s: float | None = None,
) -> RunSeries:
    """Integrate the closed loop for `duration_s` at step `dt_s`; every step is recorded.

    `estimator_dt_s` (default `dt_s`) runs the estimator at its own, faster rate: it
    must divide `dt_s`.  Information then crosses a link per estimator step, as in
    the followers whose estimator advances on message arrival.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
    substeps = estimator_substeps(dt_s, estimator_dt_s)
    compiled = engine == "numba" or (engine == "auto" and lockstep_kernel.HAVE_NUMBA)
    steps = round(duration_s / dt_s)
    t = np.arange(steps + 1, dtype=np.float64) * dt_s
    targets, _ = TargetMotion(scenario, horizon_s=duration_s).states(t)
    # Observations are exact here, so p~ and its finite-difference rate are precomputed.
    p_tilde = np.einsum("ij,kjd->kid", observation_weights(scenario.observation()), targets)
    p_tilde_rate = np.zeros_like(p_tilde)
    p_tilde_rate[1:] = np.diff(p_tilde, axis=0) / dt_s
    pos = np.zeros(p_tilde.shape[:2], np.complex128)
    pos[0] = as_complex(np.asarray(scenario.follower_pos_m, np.float64))
    est, cmd = np.zeros_like(pos), np.zeros_like(pos)
    args = (dt_s, substeps, *_graph_and_law(scenario, dt_s, substeps), as_complex(p_tilde),
            as_complex(p_tilde_rate), np.zeros(scenario.n, np.complex128),
            np.zeros(scenario.n, np.complex128), pos, est, cmd)
    bounds = np.linspace(0, steps + 1, min(CHUNKS, steps + 1) + 1).astype(int)
    for k0, k1 in itertools.pairwise(bounds):
        lockstep_kernel.run_steps(int(k0), int(k1), compiled, *args)
        if progress is not None:
            progress(k1 / (steps + 1))
    return RunSeries(t, as_plane(pos), as_plane(est), as_plane(cmd), targets)


def _graph_and_law(scenario: Scenario, dt_s: float, substeps: int) -> tuple[object, ...]:
    """The kernel's law vector, the graph's directed edges and their fractions, the
    successors and the desired angles."""
    pat = scenario.pattern
    adjacency = scenario.adjacency()
    tails, heads = np.nonzero(adjacency)
    law = lockstep_kernel.law_vector(estimator_params(scenario), control_gains(scenario),
                                     dt_s / substeps)
    return (law, tails, heads, edge_fractions(adjacency, tails, heads),
            np.asarray(scenario.successor), np.asarray(pat.angles_rad, np.float64))


def estimator_substeps(dt_s: float, estimator_dt_s: float | None) -> int:
    """How many estimator steps of `estimator_dt_s` make one control step of `dt_s`."""
    if estimator_dt_s is None:
        return 1
    substeps = round(dt_s / estimator_dt_s)
    if estimator_dt_s <= 0.0 or substeps < 1 or abs(substeps * estimator_dt_s - dt_s) > 1e-9:
        raise ValueError(
            f"estimator_dt_s must divide dt_s ({dt_s:g} s) into whole steps, got {estimator_dt_s:g}"
        )
    return substeps
