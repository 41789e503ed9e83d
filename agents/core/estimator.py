"""The paper's continuous finite-time LAP estimator (eq. smoothingEstimator), as pure functions.

    r_i = Phi_i + p~_i,   dPhi_i/dt = k_e * sum_j a_ij sig(r_j - r_i)^(1/alpha1)

with p~_i = (n/m) * sum_{j in N_i^T} p_j^t / |N_j^F|.  Nothing here knows about
clocks or networks: time steps and neighbour values are arguments.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

# The parameters and the one-follower twins live without numpy, for the follower process.
from agents.core.estimator_one import EstimatorParams as EstimatorParams
from agents.core.estimator_one import consensus_flows_c as consensus_flows_c
from agents.core.estimator_one import finite_difference_velocity as finite_difference_velocity
from agents.core.estimator_one import lag_free_velocity as lag_free_velocity
from agents.core.estimator_one import link_balance_c as link_balance_c
from agents.core.geometry import limited_sig, rate_cap

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


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
