"""Who is in the swarm, and the ring it forms: pure and deterministic, no I/O, no clock.

Every follower (and the simulator's sensor model) calls `membership(scenario, members)`
with the member set it derived from Zenoh liveliness; the same set gives the same
result everywhere, so no coordinator is needed for the followers to agree.

Rules, all from the scenario and the member set only:
- Graph: the scenario's edges between members, plus, for every connected group of
  absent followers (connected in the scenario graph), a path through the members
  adjacent to that group, in ring order.  A ring's leaver thus has its two neighbours
  link to each other; on any graph, every path that ran through absent followers is
  replaced by one through their surviving neighbours, so the graph stays connected.
- Successor: the next member along the scenario's successor cycle (absent ones skipped).
- Angles (`Pattern.rebalance`): "scale" multiplies the members' own angles so they sum
  to 2 pi (a uniform ring stays uniform); "keep" merges each absent follower's angle
  into its predecessor's, so every member keeps its gap to the next member as planned.
- Observers: a target keeps its scenario observers that are members; a target left
  with none goes to the first member after its first scenario observer in ring order.
- Weights of p~: the paper's W_ij = (n/m) o_ij / |N_j^F| with n the member count, so
  the members' p~ still average to the LAP.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from agents.membership.graph_weights import edge_fraction, observation_weight
from agents.scenario.model import Scenario, adjacency_matrix

# numpy only for the lock-step engine's matrices: the follower process forms its ring
# from `weight_row` and `edge_fraction` and must not import numpy (issue 15).
if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    FloatArray = NDArray[np.float64]
REBALANCE_POLICIES = ("scale", "keep")


@dataclass(frozen=True)
class Membership:
    """The swarm as formed by `members` (0-based follower indices, sorted)."""

    n_total: int
    members: tuple[int, ...]
    edges: tuple[tuple[int, int], ...]  # undirected, (a, b) with a < b, sorted
    successor: dict[int, int]  # member -> next member in the ring
    angles_rad: dict[int, float]  # member -> its gap to its successor; sum 2 pi
    observers: tuple[tuple[int, ...], ...]  # per target, the members observing it

    def neighbours(self, i: int) -> tuple[int, ...]:
        return tuple(sorted({b for a, b in self.edges if a == i} | {a for a, b in self.edges
                                                                     if b == i}))

    def edge_fraction(self, i: int, j: int) -> float:
        """The edge i -> j's graph_weights.edge_fraction."""
        return edge_fraction(len(self.neighbours(i)), len(self.neighbours(j)))

    def weight_row(self, i: int) -> tuple[float, ...]:
        """Follower i's row of W (m,): p~_i = row @ targets, over the members only."""
        n, m = len(self.members), len(self.observers)
        return tuple(observation_weight(n, m, len(obs)) if i in obs else 0.0
                     for obs in self.observers)

    def adjacency(self) -> FloatArray:
        """(n_total, n_total) 0/1 adjacency; rows of absent followers are zero."""
        return adjacency_matrix(self.n_total, self.edges)

    def weights(self) -> FloatArray:
        """(n_total, m) W with p~_i = W[i] @ targets, over the members only."""
        import numpy as np

        return np.array([self.weight_row(i) for i in range(self.n_total)]).reshape(
            self.n_total, len(self.observers))


def ring_order(successor: tuple[int, ...]) -> tuple[int, ...]:
    """The followers in successor order, starting at 0."""
    order, i = [0], successor[0]
    while i != 0 and len(order) < len(successor):
        order.append(i)
        i = successor[i]
    return tuple(order)


def live_successor(order: tuple[int, ...], members: frozenset[int]) -> dict[int, int]:
    """Member -> the next member along the ring `order` (itself when alone)."""
    live = [i for i in order if i in members]
    return {i: live[(k + 1) % len(live)] for k, i in enumerate(live)}


def rebalanced_angles(
    angles_rad: tuple[float, ...], order: tuple[int, ...], members: frozenset[int], policy: str
) -> dict[int, float]:
    """Each member's gap to its live successor; the gaps sum to 2 pi (see module doc)."""
    live = [i for i in order if i in members]
    if policy == "scale":
        total = sum(angles_rad[i] for i in live)
        return {i: angles_rad[i] * 2.0 * math.pi / total for i in live}
    if policy != "keep":
        raise ValueError(f"rebalance policy must be one of {REBALANCE_POLICIES}, got {policy!r}")
    out: dict[int, float] = {}
    start = order.index(live[0])
    owner = live[0]
    for k in range(len(order)):  # walk the ring once from a member: absent gaps go to owner
        i = order[(start + k) % len(order)]
        if i in members:
            owner = i
        out[owner] = out.get(owner, 0.0) + angles_rad[i]
    return out


def _absent_groups(
    n: int, edges: Iterable[tuple[int, int]], members: frozenset[int]
) -> list[set[int]]:
    """Connected groups of absent followers in the scenario graph."""
    absent = {i for i in range(n) if i not in members}
    adj: dict[int, set[int]] = {i: set() for i in range(n)}
    for a, b in edges:
        adj[a].add(b)
        adj[b].add(a)
    groups: list[set[int]] = []
    while absent:
        group, frontier = set(), [min(absent)]
        while frontier:
            i = frontier.pop()
            if i in group:
                continue
            group.add(i)
            frontier.extend(j for j in adj[i] if j in absent and j not in group)
        absent -= group
        groups.append(group)
    return groups


def bridged_edges(
    n: int, edges: tuple[tuple[int, int], ...], order: tuple[int, ...], members: frozenset[int]
) -> tuple[tuple[int, int], ...]:
    """Scenario edges among members plus, per absent group, a path through its boundary."""
    out = {(min(a, b), max(a, b)) for a, b in edges if a in members and b in members}
    rank = {i: k for k, i in enumerate(order)}
    for group in _absent_groups(n, edges, members):
        boundary = {b for a, b in edges if a in group and b in members}
        boundary |= {a for a, b in edges if b in group and a in members}
        # Ring order starting after the group, so a ring's two boundary members are
        # linked directly whatever their indices.
        first = min(rank[i] for i in group)
        path = sorted(boundary, key=lambda i: (rank[i] - first) % n)
        out |= {(min(a, b), max(a, b)) for a, b in itertools.pairwise(path)}
    return tuple(sorted(out))


def reassigned_observers(
    scenario: Scenario, order: tuple[int, ...], members: frozenset[int]
) -> tuple[tuple[int, ...], ...]:
    """Per target, its member observers; an orphan goes to the next member in ring order."""
    out = []
    for target in scenario.targets:
        live = tuple(sorted(i for i in target.observed_by if i in members))
        if not live:
            k = order.index(min(target.observed_by, key=order.index))
            live = next(
                (order[(k + s) % len(order)],)
                for s in range(len(order))
                if order[(k + s) % len(order)] in members
            )
        out.append(live)
    return tuple(out)


def membership(scenario: Scenario, members: Iterable[int]) -> Membership:
    """The swarm formed by `members`; ValueError if it is empty or names unknown followers."""
    live = frozenset(int(i) for i in members)
    if not live or not live <= set(range(scenario.n)):
        raise ValueError(f"members must be a non-empty subset of 0..{scenario.n - 1}: {live}")
    order = ring_order(scenario.successor)
    return Membership(
        n_total=scenario.n,
        members=tuple(sorted(live)),
        edges=bridged_edges(scenario.n, scenario.edges, order, live),
        successor=live_successor(order, live),
        angles_rad=rebalanced_angles(
            scenario.pattern.angles_rad, order, live, scenario.pattern.rebalance
        ),
        observers=reassigned_observers(scenario, order, live),
    )
