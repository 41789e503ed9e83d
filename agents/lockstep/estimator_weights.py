"""The estimator's weights (agents.membership.graph_weights) as numpy matrices, for the
lock-step engine, which sees the whole swarm at once (the follower process forms its own
row: agents.membership.ring).  The laws themselves are agents.law's."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from agents.membership.graph_weights import edge_fraction, observation_weight

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def observation_weights(observation: FloatArray) -> FloatArray:
    """(n, m) weights W with p~ = W @ targets: W_ij = observation_weight of target j where
    follower i observes it, else 0."""
    n, m = observation.shape
    counts = observation.sum(axis=0)
    if np.any(counts < 1):
        raise ValueError("every target must be observed by at least one follower")
    return np.array([[observation_weight(n, m, int(counts[j])) if observation[i, j] else 0.0
                      for j in range(m)] for i in range(n)], np.float64).reshape(n, m)


def edge_fractions(adjacency: FloatArray, tails: IntArray, heads: IntArray) -> FloatArray:
    """Per directed edge tails[k] -> heads[k], its edge_fraction."""
    degree = adjacency.sum(axis=1).astype(int)
    return np.array([edge_fraction(int(degree[a]), int(degree[b]))
                     for a, b in zip(tails, heads, strict=True)], np.float64)
