"""The estimator's graph weights, written once: pure scalars, no numpy.

    p~_i = (n/m) * sum_{j in N_i^T} p_j^t / |N_j^F|,   edge fractions 1 / max(deg_i, deg_j)

A follower forms its own row from these (agents.membership.ring); the lock-step engine,
which sees the whole swarm at once, lays the same numbers out as matrices
(agents.lockstep.estimator_weights).
"""

from __future__ import annotations


def observation_weight(n: int, m: int, observers: int) -> float:
    """W_ij of a follower that observes target j: (n/m) / |N_j^F|, with n followers,
    m targets and `observers` = |N_j^F| followers observing target j (0 if it does not)."""
    if observers < 1:
        raise ValueError(f"observers={observers}: every target must be observed by at "
                         "least one follower")
    return n / m / observers


def edge_fraction(degree_i: int, degree_j: int) -> float:
    """The edge i -> j's fraction 1 / max(deg_i, deg_j): Metropolis-like weights keep the
    linear (capped) regime of the consensus a stable averaging on any graph, from local
    data."""
    return 1.0 / max(degree_i, degree_j)
