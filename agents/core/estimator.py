"""The paper's continuous finite-time LAP estimator (eq. smoothingEstimator), as pure functions.

    r_i = Phi_i + p~_i,   dPhi_i/dt = k_e * sum_j a_ij sig(r_j - r_i)^(1/alpha1)

with p~_i = (n/m) * sum_{j in N_i^T} p_j^t / |N_j^F|.  Nothing here knows about
clocks or networks: time steps and neighbour values are arguments.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from agents.core.geometry import limited_sig, limited_sig_one, rate_cap

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
# A plane vector: a (2,) array, or x + iy (the networked follower's scalar twins).
Vec = TypeVar("Vec", FloatArray, complex)


def observation_weights(observation: FloatArray) -> FloatArray:
    """(n, m) weights W with p~ = W @ targets: W_ij = (n/m) * o_ij / |N_j^F|."""
    n, m = observation.shape
    counts = observation.sum(axis=0)
    if np.any(counts < 1):
        raise ValueError("every target must be observed by at least one follower")
    return (n / m) * observation / counts[None, :]


def local_reference(weights_row: FloatArray, observed_pos_m: FloatArray) -> FloatArray:
    """p~ for followers whose weight rows are `weights_row` ((k, m) or (m,)) and targets (m, 2)."""
    return weights_row @ observed_pos_m


@dataclass(frozen=True)
class EstimatorParams:
    """k_e and alpha1 of the paper; `step_fraction` caps one step's flow (0: plain Euler)."""

    k_e: float
    alpha1: float
    step_fraction: float = 0.5


def edge_fractions(adjacency: FloatArray, tails: IntArray, heads: IntArray) -> FloatArray:
    """Per directed edge 1 / max(deg_i, deg_j): Metropolis-like weights keep the linear
    (capped) regime of the consensus a stable averaging on any graph, from local data."""
    degree = adjacency.sum(axis=1)
    return 1.0 / np.maximum(degree[tails], degree[heads])


def consensus_flows(
    r_self_m: FloatArray,
    r_nbrs_m: FloatArray,
    nbr_fractions: FloatArray,
    params: EstimatorParams,
    dt_s: float,
) -> FloatArray:
    """(d, 2) flows of one follower's links: k_e sig(r_j - r_i)^(1/alpha1), step-limited."""
    cap = rate_cap(params.step_fraction, dt_s) * nbr_fractions[:, None]
    return limited_sig(r_nbrs_m - r_self_m, 1.0 / params.alpha1, params.k_e, cap)


def consensus_flows_c(
    r_self_m: complex,
    r_nbrs_m: Sequence[complex],
    nbr_fractions: Sequence[float],
    params: EstimatorParams,
    dt_s: float,
) -> list[complex]:
    """`consensus_flows` with plane vectors as complex x + iy (one list entry per link):
    the same law, component by component, without numpy's per-call cost."""
    base, exponent, gain = rate_cap(params.step_fraction, dt_s), 1.0 / params.alpha1, params.k_e
    flows = []
    for r_j, fraction in zip(r_nbrs_m, nbr_fractions, strict=True):
        gap, cap = r_j - r_self_m, base * fraction
        flows.append(complex(limited_sig_one(gap.real, exponent, gain, cap),
                             limited_sig_one(gap.imag, exponent, gain, cap)))
    return flows


def consensus_rate(
    r_self_m: FloatArray,
    r_nbrs_m: FloatArray,
    nbr_fractions: FloatArray,
    params: EstimatorParams,
    dt_s: float,
) -> FloatArray:
    """dPhi/dt of one follower from its r (2,), its neighbours' r (d, 2) and edge fractions (d,)."""
    flows = consensus_flows(r_self_m, r_nbrs_m, nbr_fractions, params, dt_s)
    return np.asarray(flows.sum(axis=0))


def link_balance(own_sums_m: FloatArray, their_sums_m: FloatArray) -> FloatArray:
    """Phi of the robust estimator: half the difference of each link's two running sums.

    Follower i integrates its own flow on link j into S_ij; j does the same into
    S_ji and publishes it.  Phi_i = sum_j (S_ij - S_ji) / 2 makes every link's
    contributions to Phi_i and Phi_j exact opposites, whatever was lost or late,
    so sum(Phi) = 0 (mean r = LAP) holds up to the sums still in flight; with the
    paper's increments a lost or late message shifts the mean for good.
    """
    return np.asarray(0.5 * (own_sums_m - their_sums_m).sum(axis=0))


def link_balance_c(own_sums_m: Sequence[complex], their_sums_m: Sequence[complex]) -> complex:
    """`link_balance` with plane vectors as complex x + iy, one per link."""
    total = 0j
    for own, theirs in zip(own_sums_m, their_sums_m, strict=True):
        total += own - theirs
    return 0.5 * total


@dataclass(frozen=True)
class EdgeOperators:
    """Linear maps of an undirected graph, built once: r -> r_j - r_i per directed edge and back."""

    difference: FloatArray  # (2E, n): row e is +1 at the edge's head j, -1 at its tail i
    gather: FloatArray  # (n, 2E): sums each follower's outgoing edges
    fractions: FloatArray  # (2E, 1): edge_fractions of each directed edge

    @staticmethod
    def from_adjacency(adjacency: FloatArray) -> EdgeOperators:
        tails, heads = np.nonzero(adjacency)
        n, count = adjacency.shape[0], len(tails)
        difference = np.zeros((count, n))
        difference[np.arange(count), heads] += 1.0
        difference[np.arange(count), tails] -= 1.0
        gather = np.zeros((n, count))
        gather[tails, np.arange(count)] = adjacency[tails, heads]
        fractions = edge_fractions(adjacency, tails, heads)[:, None]
        return EdgeOperators(difference, gather, fractions)


def estimator_rate(
    r_m: FloatArray, edges: EdgeOperators, params: EstimatorParams, dt_s: float
) -> FloatArray:
    """dPhi/dt for all followers at once: (n, 2) from r (n, 2).

    Every edge's flow is odd in r_j - r_i, so the flows cancel in pairs and the
    sum of dPhi is zero: mean(r) stays the LAP.
    """
    cap = rate_cap(params.step_fraction, dt_s) * edges.fractions
    flow = limited_sig(edges.difference @ r_m, 1.0 / params.alpha1, params.k_e, cap)
    return np.asarray(edges.gather @ flow)


def estimate(phi_m: FloatArray, p_tilde_m: FloatArray) -> FloatArray:
    """r = Phi + p~."""
    return phi_m + p_tilde_m


def step_phi(phi_m: FloatArray, phi_rate_m_s: FloatArray, dt_s: float) -> FloatArray:
    """Explicit Euler step of the estimator's integrator state."""
    return phi_m + dt_s * phi_rate_m_s


def finite_difference_velocity(
    prev_pos_m: Vec,
    prev_stamp_s: float,
    pos_m: Vec,
    stamp_s: float,
    prev_vel_m_s: Vec,
    tau_s: float = 0.0,
) -> Vec:
    """Velocity from two timestamped observations, optionally low-passed with time constant tau.

    A zero or negative stamp difference (duplicate or reordered data) keeps the old estimate.
    Vectors are (2,) arrays or complex x + iy: plain arithmetic, the same for both.
    """
    dt = stamp_s - prev_stamp_s
    if dt <= 0.0:
        return prev_vel_m_s
    raw = (pos_m - prev_pos_m) / dt
    if tau_s <= 0.0:
        return raw
    gain = dt / (tau_s + dt)
    return prev_vel_m_s + gain * (raw - prev_vel_m_s)
