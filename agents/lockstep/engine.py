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
from numpy.typing import NDArray

from agents.analysis.geometry import as_complex, as_plane
from agents.analysis.timeseries import RunSeries
from agents.law.scenario_params import control_gains, estimator_params
from agents.lockstep import kernel as lockstep_kernel
from agents.lockstep.estimator_weights import edge_fractions, observation_weights
from agents.lockstep.held_observations import RangedSensing, held_p_tilde, sensed_targets
from agents.scenario.model import Scenario
from agents.scenario.target_motion import TargetMotion
from agents.scenario.weather_tables import WindConfig
from agents.weather.gps import GpsNoise
from agents.weather.gusts import WindField, steady_leak
from agents.weather.windows import gust_std_at, wind_windows

ProgressFn = Callable[[float], None]
FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
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
    # Observations without a sensor range do not depend on the followers (exact, or
    # agents.lockstep.held_observations): p~ and its rate are precomputed; with one, each
    # step draws them from where the followers are (`_ranged`).
    weights = observation_weights(scenario.observation())
    held = sensed_targets(scenario, t, targets)  # [sensing]; None: exact observations
    p_tilde = (np.einsum("ij,kjd->kid", weights, targets) if held is None
               else held_p_tilde(held, weights))
    p_tilde_rate = np.zeros_like(p_tilde)
    p_tilde_rate[1:] = np.diff(p_tilde, axis=0) / dt_s
    pos = np.zeros(p_tilde.shape[:2], np.complex128)
    pos[0] = as_complex(np.asarray(scenario.follower_pos_m, np.float64))
    est, cmd = np.zeros_like(pos), np.zeros_like(pos)
    pt, pt_rate, gps = as_complex(p_tilde), as_complex(p_tilde_rate), lockstep_gps(scenario, t)
    args = (dt_s, substeps, *_graph_and_law(scenario, dt_s, substeps), pt, pt_rate,
            np.zeros(scenario.n, np.complex128), np.zeros(scenario.n, np.complex128), pos,
            est, cmd, *lockstep_wind(scenario, t), gps)
    ranged = _ranged(scenario, weights, substeps)
    bounds = np.linspace(0, steps + 1, min(CHUNKS, steps + 1) + 1).astype(int)
    for k0, k1 in itertools.pairwise(bounds):
        if ranged is None:
            lockstep_kernel.run_steps(int(k0), int(k1), compiled, *args)
        else:
            for k in range(int(k0), int(k1)):
                # p~ of step k from where the followers are at step k, then that one step
                reported = pos[k] + gps[k] if len(gps) else pos[k]
                pt[k] = as_complex(ranged.p_tilde(float(t[k]), targets[k], as_plane(pos[k]),
                                                  as_plane(reported)))
                pt_rate[k] = (pt[k] - pt[k - 1]) / dt_s if k > 0 else 0j
                lockstep_kernel.run_steps(k, k + 1, compiled, *args)
        if progress is not None:
            progress(k1 / (steps + 1))
    return RunSeries(t, as_plane(pos), as_plane(est), as_plane(cmd), targets)


def _ranged(scenario: Scenario, weights: FloatArray, substeps: int) -> RangedSensing | None:
    """A sensor with a range: drawn step by step from the followers' positions."""
    cfg = scenario.sensing
    if cfg is None or cfg.is_perfect or cfg.max_range_m is None:
        return None
    if substeps > 1:  # the estimator's substeps read the next step's p~ rate
        raise ValueError("a sensor with max_range_m runs lock-step with no faster estimator")
    return RangedSensing(scenario, weights)


def lockstep_wind(scenario: Scenario, t: FloatArray) -> tuple[ComplexArray, float]:
    """Each step's wind per follower as x + iy, and the share of it a vehicle lets through
    (agents.weather.gusts); no rows without `[wind]`: the loop is then as it always was.
    The field holds the targets' rows too, as the simulator's does, so a seed draws alike."""
    windows = wind_windows(scenario.faults)
    wind = scenario.wind or (WindConfig() if windows else None)
    if wind is None:
        return np.zeros((0, scenario.n), np.complex128), 0.0
    field = WindField(wind, scenario.n + scenario.m)
    out = np.zeros((t.shape[0], scenario.n), np.complex128)
    out[0] = as_complex(field.velocity()[: scenario.n])
    for k in range(1, t.shape[0]):
        field.std_m_s = gust_std_at(windows, float(t[k]), wind.gust_std_m_s)
        out[k] = as_complex(field.advance(float(t[k] - t[k - 1]))[: scenario.n])
    return out, steady_leak(wind.drag_1_s, scenario.vehicle.tau_s)


def lockstep_gps(scenario: Scenario, t: FloatArray) -> ComplexArray:
    """Each step's GPS error per follower as x + iy (agents.weather.gps), drawn as the
    simulator draws it for its vehicles; no rows when the vehicles report exactly."""
    if not scenario.vehicle.gps_noisy:
        return np.zeros((0, scenario.n), np.complex128)
    gps = GpsNoise(scenario.vehicle, scenario.n + scenario.m)
    out = np.zeros((t.shape[0], scenario.n), np.complex128)
    for k in range(1, t.shape[0]):
        out[k] = as_complex(gps.advance(float(t[k] - t[k - 1]))[: scenario.n])
    return out


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
