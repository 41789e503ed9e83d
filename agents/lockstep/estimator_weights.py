"""The estimator's weights from the graph and the observations, as numpy matrices.

    p~_i = (n/m) * sum_{j in N_i^T} p_j^t / |N_j^F|,   edge fractions 1 / max(deg_i, deg_j)

for the lock-step engine, which sees the whole swarm at once (the follower process forms
its own row: agents.membership.ring).  The laws themselves are agents.law's.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def observation_weights(observation: FloatArray) -> FloatArray:
    """(n, m) weights W with p~ = W @ targets: W_ij = (n/m) * o_ij / |N_j^F|."""
    n, m = observation.shape
    counts = observation.sum(axis=0)
    if np.any(counts < 1):
        raise ValueError("every target must be observed by at least one follower")
    return (n / m) * observation / counts[None, :]


def edge_fractions(adjacency: FloatArray, tails: IntArray, heads: IntArray) -> FloatArray:
    """Per directed edge 1 / max(deg_i, deg_j): Metropolis-like weights keep the linear
    (capped) regime of the consensus a stable averaging on any graph, from local data."""
    degree = adjacency.sum(axis=1)
    return 1.0 / np.maximum(degree[tails], degree[heads])
