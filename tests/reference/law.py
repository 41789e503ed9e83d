"""The paper's law in plain numpy (tests/reference): what agents.law is compared with."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agents.law.consensus import EstimatorParams
from agents.law.enclosing import ControlGains

FloatArray = NDArray[np.float64]
NO_CAP_PER_S = 1e12
MIN_RANGE_M = 1e-9


def sig(x: FloatArray, exponent: float) -> FloatArray:
    """sig(x)^a = sign(x) * |x|^a, elementwise (the paper's odd-ratio power)."""
    return np.sign(x) * np.abs(x) ** exponent


def limited_sig(x: FloatArray, exponent: float, gain: float,
                cap_per_s: FloatArray | float) -> FloatArray:
    """gain * sig(x)^a with its magnitude capped at cap_per_s * |x|."""
    capped = np.minimum(gain * np.abs(x) ** exponent, cap_per_s * np.abs(x))
    return np.where(x < 0.0, -capped, capped)


def rate_cap(step_fraction: float, dt_s: float) -> float:
    """One step may remove `step_fraction` of an error; none: a cap that never binds."""
    return step_fraction / dt_s if step_fraction > 0.0 else NO_CAP_PER_S


@dataclass(frozen=True)
class Edges:
    """A graph's directed edges (i -> j for a_ij = 1) and their Metropolis fractions."""

    tails: NDArray[np.intp]
    heads: NDArray[np.intp]
    fractions: FloatArray

    @staticmethod
    def of(adjacency: FloatArray) -> Edges:
        tails, heads = np.nonzero(adjacency)
        degree = adjacency.sum(axis=1)
        return Edges(tails, heads, 1.0 / np.maximum(degree[tails], degree[heads]))


def edge_flows(r_m: FloatArray, edges: Edges, params: EstimatorParams, dt_s: float) -> FloatArray:
    """(E, 2) k_e sig(r_j - r_i)^(1/alpha1) per directed edge i -> j, step-limited."""
    cap = rate_cap(params.step_fraction, dt_s) * edges.fractions[:, None]
    return limited_sig(r_m[edges.heads] - r_m[edges.tails], 1.0 / params.alpha1, params.k_e, cap)


def consensus_rate(r_m: FloatArray, edges: Edges, params: EstimatorParams,
                   dt_s: float) -> FloatArray:
    """(n, 2) dPhi_i/dt = k_e sum_j a_ij sig(r_j - r_i)^(1/alpha1) of every follower."""
    rate = np.zeros_like(r_m)
    np.add.at(rate, edges.tails, edge_flows(r_m, edges, params, dt_s))
    return rate


def estimator_rates(r_m: FloatArray, psi_m_s: FloatArray, p_tilde_rate_m_s: FloatArray,
                    edges: Edges, params: EstimatorParams,
                    dt_s: float) -> tuple[FloatArray, FloatArray]:
    """(dPhi/dt, dPsi/dt) of every follower.  Order 2 (the velocity stage): the same
    consensus on rv = Psi + dp~/dt, and dPhi/dt = consensus + Psi."""
    phi_rate = consensus_rate(r_m, edges, params, dt_s)
    if params.order == 1:
        return phi_rate, np.zeros_like(psi_m_s)
    return phi_rate + psi_m_s, consensus_rate(psi_m_s + p_tilde_rate_m_s, edges, params, dt_s)


def link_balance(own_sums_m: FloatArray, their_sums_m: FloatArray) -> FloatArray:
    """Phi_i = sum_j (S_ij - S_ji) / 2 of (d, 2) link sums."""
    return np.asarray((own_sums_m - their_sums_m).sum(axis=0) / 2.0)


def rotate_ccw(vec: FloatArray) -> FloatArray:
    """(..., 2) vectors rotated by +90 degrees."""
    return np.stack([-vec[..., 1], vec[..., 0]], axis=-1)


def bearing(vec: FloatArray) -> FloatArray:
    return np.arctan2(vec[..., 1], vec[..., 0])


def spacing_step_s(gains: ControlGains, dt_s: float, succ_age_s: float) -> float:
    """dt, or the age of the successor's data where gain x age would exceed the limit
    (spacing_gain_age, 0: step_fraction / 2) for the spacing gain step_fraction / (2 step)."""
    if gains.step_fraction <= 0.0:
        return max(dt_s, succ_age_s)
    limit = gains.spacing_gain_age or 0.5 * gains.step_fraction
    gain = 0.5 * gains.step_fraction / dt_s
    return dt_s if gain * succ_age_s <= limit else 0.5 * gains.step_fraction * succ_age_s / limit


@dataclass(frozen=True)
class Control:
    u_m_s: FloatArray  # (k, 2)
    z_m: FloatArray  # (k,)
    delta: FloatArray  # (k,)


def enclosing_control(pos_m: FloatArray, succ_pos_m: FloatArray, r_m: FloatArray,
                      r_rate_m_s: FloatArray, angles_rad: FloatArray, gains: ControlGains,
                      dt_s: float, succ_age_s: float = 0.0) -> Control:
    """u_i = phi_i (-k_z sig(z_i)^(1/alpha2)) + phi_perp_i (k_d sig(delta_i)^(1/alpha3)
    + w_d rho'_i) + dr_i/dt on (k, 2) rows; the gap read within half a turn of a_i."""
    rel = pos_m - r_m
    rho = np.maximum(np.hypot(rel[:, 0], rel[:, 1]), MIN_RANGE_M)
    phi = rel / rho[:, None]
    z = rho - gains.rho_d_m
    gap = bearing(succ_pos_m - r_m) - bearing(rel)
    delta = (np.mod(gap - angles_rad + np.pi, 2.0 * np.pi) - np.pi) / angles_rad
    w_z = limited_sig(z, 1.0 / gains.alpha2, gains.k_z, rate_cap(gains.step_fraction, dt_s))
    step_s = spacing_step_s(gains, dt_s, succ_age_s)
    delta_cap = 0.5 * rate_cap(gains.step_fraction, step_s) * rho * angles_rad
    w_t = limited_sig(delta, 1.0 / gains.alpha3, gains.k_d, delta_cap) + gains.w_d_rad_s * rho
    u = -w_z[:, None] * phi + w_t[:, None] * rotate_ccw(phi) + r_rate_m_s
    return Control(u, z, delta)


def target_velocity(pos_m: FloatArray, stamps_s: FloatArray, tau_s: float,
                    accel_tau_s: float) -> tuple[FloatArray, FloatArray]:
    """(plain low-passed, lag-free) velocity after each observation of (k, 2) positions:
    v_k = s_k + a_k (tau + dt_k / 2), s the low-passed finite difference (primed with the
    first raw one) and a its low-passed rate."""
    smooth = (pos_m[1] - pos_m[0]) / (stamps_s[1] - stamps_s[0])
    accel = np.zeros(2)
    plain, lag_free = [smooth], [smooth]
    for k in range(2, len(stamps_s)):
        dt = stamps_s[k] - stamps_s[k - 1]
        raw = (pos_m[k] - pos_m[k - 1]) / dt
        new = smooth + dt / (tau_s + dt) * (raw - smooth)
        accel = accel + dt / (accel_tau_s + dt) * ((new - smooth) / dt - accel)
        smooth = new
        plain.append(smooth)
        lag_free.append(smooth + accel * (tau_s + dt / 2.0))
    return np.array(plain), np.array(lag_free)
