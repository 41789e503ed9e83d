"""In-process lock-step integration of the paper's closed loop: no clock, no network.

Followers are single integrators p' = u (explicit Euler at dt).  Target positions
are sampled at every step; followers use only the targets they observe, and
estimate the targets' velocities by finite differences of those observations,
as the networked followers do.  Two engines run the same law: "numpy" calls the
vectorised reference functions, "numba" a compiled twin (agents.core.fastloop).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agents.core import fastloop
from agents.core.controller import enclosing_control
from agents.core.estimator import (
    EdgeOperators,
    EstimatorParams,
    edge_fractions,
    estimator_rate,
    observation_weights,
)
from agents.core.geometry import rate_cap
from agents.core.params import control_gains, estimator_params
from agents.core.profiles import TargetMotion
from agents.core.timeseries import RunSeries
from agents.scenario.model import Scenario

FloatArray = NDArray[np.float64]
ProgressFn = Callable[[float], None]
ENGINES = ("auto", "numpy", "numba")
CHUNKS = 100


@dataclass
class _Loop:
    """Inputs and in-place outputs of one lock-step run."""

    scenario: Scenario
    dt_s: float
    substeps: int  # estimator steps per control step (the estimator's own, faster rate)
    p_tilde: FloatArray  # (k, n, 2) references from exact observations
    p_tilde_rate: FloatArray  # (k, n, 2) their finite-difference rates
    phi: FloatArray  # (n, 2) estimator state
    psi: FloatArray  # (n, 2) its velocity stage's (estimator order 2; stays zero at order 1)
    pos: FloatArray  # (k, n, 2)
    est: FloatArray
    cmd: FloatArray

    def numpy_steps(self, k0: int, k1: int) -> None:
        s, dt, sub = self.scenario, self.dt_s, self.substeps
        dt_e = dt / sub
        edges = EdgeOperators.from_adjacency(s.adjacency())
        params, gains = estimator_params(s), control_gains(s)
        succ, angles = np.asarray(s.successor), np.asarray(s.pattern.angles_rad)
        phi, psi = self.phi, self.psi
        for k in range(k0, k1):
            r = phi + self.p_tilde[k]
            phi_rate, psi_rate = self._rates(r, psi, self.p_tilde_rate[k], edges, params, dt_e)
            p = self.pos[k]
            out = enclosing_control(
                p, p[succ], r, phi_rate + self.p_tilde_rate[k], angles, gains, dt
            )
            self.est[k] = r
            self.cmd[k] = out.u_m_s
            if k + 1 < len(self.pos):
                self.pos[k + 1] = p + dt * out.u_m_s
                phi, psi = phi + dt_e * phi_rate, psi + dt_e * psi_rate
                # Between control steps p~ moves linearly to its next sample.
                for j in range(1, sub):
                    r = phi + self.p_tilde[k] + (j * dt_e) * self.p_tilde_rate[k + 1]
                    phi_rate, psi_rate = self._rates(
                        r, psi, self.p_tilde_rate[k + 1], edges, params, dt_e)
                    phi, psi = phi + dt_e * phi_rate, psi + dt_e * psi_rate
        self.phi[:], self.psi[:] = phi, psi

    @staticmethod
    def _rates(r: FloatArray, psi: FloatArray, p_tilde_rate: FloatArray, edges: EdgeOperators,
               params: EstimatorParams, dt_e: float) -> tuple[FloatArray, FloatArray]:
        """dPhi/dt and dPsi/dt: the velocity stage agrees on psi + dp~/dt and feeds psi in."""
        phi_rate = estimator_rate(r, edges, params, dt_e)
        if params.order == 1:
            return phi_rate, np.zeros_like(psi)
        return phi_rate + psi, estimator_rate(psi + p_tilde_rate, edges, params, dt_e)

    def numba_steps(self, k0: int, k1: int) -> None:
        s = self.scenario
        g, pat = s.gains, s.pattern
        adjacency = s.adjacency()
        tails, heads = np.nonzero(adjacency)
        gains = np.array(
            [g.k_e, g.alpha1, g.k_z, g.alpha2, g.k_d, g.alpha3, pat.rho_d_m, pat.w_d_rad_s,
             rate_cap(g.step_fraction, self.dt_s), g.estimator_order]
        )
        fastloop.run_steps(
            k0,
            k1,
            self.dt_s,
            self.substeps,
            rate_cap(g.est_step_fraction, self.dt_s / self.substeps),
            gains,
            tails,
            heads,
            edge_fractions(adjacency, tails, heads),
            np.asarray(s.successor),
            np.asarray(pat.angles_rad),
            self.p_tilde,
            self.p_tilde_rate,
            self.phi,
            self.psi,
            self.pos,
            self.est,
            self.cmd,
        )


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
    use_numba = engine == "numba" or (engine == "auto" and fastloop.HAVE_NUMBA)
    steps = round(duration_s / dt_s)
    t = np.arange(steps + 1, dtype=np.float64) * dt_s
    targets, _ = TargetMotion(scenario, horizon_s=duration_s).states(t)
    # Observations are exact here, so p~ and its finite-difference rate are precomputed.
    p_tilde = np.einsum("ij,kjd->kid", observation_weights(scenario.observation()), targets)
    p_tilde_rate = np.zeros_like(p_tilde)
    p_tilde_rate[1:] = np.diff(p_tilde, axis=0) / dt_s
    pos = np.empty_like(p_tilde)
    pos[0] = np.asarray(scenario.follower_pos_m)
    loop = _Loop(
        scenario,
        dt_s,
        substeps,
        p_tilde,
        p_tilde_rate,
        np.zeros((scenario.n, 2)),
        np.zeros((scenario.n, 2)),
        pos,
        np.empty_like(pos),
        np.zeros_like(pos),
    )
    advance = loop.numba_steps if use_numba else loop.numpy_steps
    bounds = np.linspace(0, steps + 1, min(CHUNKS, steps + 1) + 1).astype(int)
    for k0, k1 in itertools.pairwise(bounds):
        advance(int(k0), int(k1))
        if progress is not None:
            progress(k1 / (steps + 1))
    return RunSeries(t, loop.pos, loop.est, loop.cmd, targets)


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
