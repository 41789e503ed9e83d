"""Scenario: the frozen, validated description of one enclosing experiment.

Positions are in the local ENU plane (x east, y north) in metres.  Follower and
target numbers in TOML files are 1-based, as in the paper; everything in code
is 0-based.  Validation happens once, in `agents.loading.scenario_file`, and every
error names the offending field.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from agents.scenario.faults import FaultSpec
from agents.scenario.weather_tables import SensingConfig, WindConfig
from transport.network_schema import NetworkConfig

# numpy only where the lock-step engine asks for matrices: a follower process loads a
# Scenario too and must not import numpy (issue 15: <= 50 MB per follower).
if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    FloatArray = NDArray[np.float64]

PROFILE_KINDS = ("paper_v1", "paper_v2", "constant", "circle", "random_walk")
ESTIMATORS = ("paper", "robust")
REBALANCE = ("scale", "keep")


@dataclass(frozen=True)
class Gains:
    """Estimator and controller gains (paper Table II)."""

    k_e: float = 6.0
    alpha1: float = 7.0 / 3.0
    k_z: float = 2.0
    alpha2: float = 3.0
    k_d: float = 2.0
    alpha3: float = 3.0
    step_fraction: float = 0.5  # share of an error one sampled step may remove; 0 = plain Euler
    # The estimator's own share (None: step_fraction).  Its links' lag is ~ 1 / (share x
    # rate), while the controller's share sets how hard the commands move.
    estimator_step_fraction: float | None = None
    # 1: the paper's estimator.  2 adds a velocity stage (a second-order dynamic average
    # consensus): the followers also agree on the targets' mean velocity and feed it
    # forward, so a link no longer needs a standing gap to carry the targets' velocity
    # difference -- the gap that puts ring16 at 0.16 m at 50 Hz (issue 15).  Robust only.
    estimator_order: int = 1
    # The networked follower evaluates its law on the state it predicts this far ahead (own
    # and successor positions at their velocities, the estimate at its rate): what passes
    # between its inputs' stamp and the vehicle flying the command.  Unpredicted, that
    # delay turns the ring's slow spacing modes' rotation into growth (their decay goes as
    # g (1/2 - g L) (2 pi k / n)^2 for a spacing gain g and a delay L): ring64's k = 1 mode
    # barely decays at 20 Hz without it (issue 15).  0: the paper's law on the latest data.
    # Lock-step commands act at once, so it has nothing to lead and ignores it.
    lead_s: float = 0.0
    # The spacing law's gain g = step_fraction / (2 dt) times its successor's data age L may
    # not exceed this: above it the gain is cut to spacing_gain_age / L.  None (default):
    # step_fraction / 2, the gain falls as soon as the age exceeds a period, which keeps
    # small rings from chattering on jittered data; a large ring's slowest spacing mode
    # (k = 1, decay ~ g (2 pi / n)^2) wants the gain kept (ring64; BENCHMARKS.md, issue 15).
    spacing_gain_age: float | None = None

    @property
    def est_step_fraction(self) -> float:
        share = self.estimator_step_fraction
        return self.step_fraction if share is None else share


@dataclass(frozen=True)
class Pattern:
    """Spacing pattern P = {w_d, rho_d, a}; `angles_rad[i]` is follower i's gap to its successor."""

    rho_d_m: float
    w_d_rad_s: float
    angles_rad: tuple[float, ...]
    rebalance: str = "scale"  # when followers leave: "scale" | "keep" (agents.membership.ring)


@dataclass(frozen=True)
class TargetSpec:
    """One target: start, motion profile and the followers that observe it (0-based)."""

    initial_pos_m: tuple[float, float]
    profile: str
    observed_by: tuple[int, ...]
    vel_m_s: tuple[float, float] = (0.0, 0.0)
    center_m: tuple[float, float] = (0.0, 0.0)
    omega_rad_s: float = 0.0
    speed_max_m_s: float = 0.0
    knot_interval_s: float = 2.0
    seed: int = 0


@dataclass(frozen=True)
class RunConfig:
    """Timing of a run and the accuracy bounds its metrics are judged by."""

    duration_s: float = 200.0
    dt_s: float = 0.001
    rate_hz: float = 50.0
    # The estimator's own rate (issue 15), a whole multiple of rate_hz; None: rate_hz.
    # Information crosses one link per estimator step, so long rings need it faster.
    estimator_rate_hz: float | None = None
    steady_from_s: float | None = None
    eps_rho_m: float = 0.0999
    eps_delta: float = 0.0199
    target_start_s: float = 0.0
    # Two vehicles closer than this are a near collision: the verdict and live view say so.
    safety_distance_m: float = 1.0
    # Every follower journals its law's inputs (enclose replay) unless the command line
    # says otherwise: a swarm at the machine's edge may need the share of a core it costs.
    journal: bool = True

    @property
    def estimator_hz(self) -> float:
        return self.rate_hz if self.estimator_rate_hz is None else self.estimator_rate_hz

    @property
    def estimator_substeps(self) -> int:
        """Estimator steps per control step."""
        return round(self.estimator_hz / self.rate_hz)


@dataclass(frozen=True)
class VehicleConfig:
    """Kinematic multirotor limits used by the simulator (and expected of a real vehicle)."""

    altitude_m: float = 10.0
    tau_s: float = 0.05
    max_speed_xy_m_s: float = 12.0
    max_speed_z_m_s: float = 3.0
    max_accel_m_s2: float = 20.0
    flavour: str = "px4"
    # What the vehicle's telemetry reports of its position (agents.weather.gps): white
    # noise plus a slow random-walk bias, seeded; 0 and 0: the true position, exactly.
    gps_noise_std_m: float = 0.0
    gps_bias_walk_m_s: float = 0.0
    gps_seed: int = 0

    @property
    def gps_noisy(self) -> bool:
        return self.gps_noise_std_m > 0.0 or self.gps_bias_walk_m_s > 0.0


@dataclass(frozen=True)
class HomeConfig:
    """Geodetic origin of the local frame (PX4 SITL's default home)."""

    lat_deg: float = 47.397742
    lon_deg: float = 8.545594
    alt_m: float = 488.0


@dataclass(frozen=True)
class LawSpec:
    """The scenario's `[law]`: a shipped law by name, or the user's own class by module
    reference, and the law's own parameters (checked by the law: agents.loading.law_loader)."""

    name: str = "paper"  # a shipped law (agents.law.shipped); unused with `module`
    module: str | None = None  # "package.module:Class"
    folder: str | None = None  # absolute folder `module` is imported from
    params: tuple[tuple[str, Any], ...] = ()  # the table's other keys, file order

    @property
    def ref(self) -> str:
        """How the law is named in records and verdicts: its name, or its module reference."""
        return self.name if self.module is None else self.module

    @property
    def is_paper(self) -> bool:
        """The paper's law: the lock-step engine has a compiled path for it."""
        return self.module is None and self.name == "paper"


@dataclass(frozen=True)
class Scenario:
    """Everything one run needs; built only by `agents.loading.scenario_file`."""

    name: str
    beta_m_s: float
    follower_pos_m: tuple[tuple[float, float], ...]
    targets: tuple[TargetSpec, ...]
    edges: tuple[tuple[int, int], ...]
    successor: tuple[int, ...]
    pattern: Pattern
    gains: Gains = field(default_factory=Gains)
    run: RunConfig = field(default_factory=RunConfig)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    home: HomeConfig = field(default_factory=HomeConfig)
    network: NetworkConfig = field(default_factory=NetworkConfig)
    faults: tuple[FaultSpec, ...] = ()  # injected by the launcher (agents.scenario.faults)
    law: LawSpec = field(default_factory=LawSpec)  # [law]: what each follower flies
    wind: WindConfig | None = None  # [wind] (agents.scenario.weather_tables): None, still air
    sensing: SensingConfig | None = None  # [sensing]: None, every target seen exactly

    @property
    def n(self) -> int:
        return len(self.follower_pos_m)

    @property
    def m(self) -> int:
        return len(self.targets)

    def adjacency(self) -> FloatArray:
        """Symmetric 0/1 follower adjacency matrix a_ij."""
        return adjacency_matrix(self.n, self.edges)

    def observation(self) -> FloatArray:
        """(n, m) 0/1 matrix: follower i observes target j."""
        import numpy as np

        obs = np.zeros((self.n, self.m))
        for j, target in enumerate(self.targets):
            obs[list(target.observed_by), j] = 1.0
        return obs

    def neighbours(self, i: int) -> tuple[int, ...]:
        return tuple(
            sorted({b for a, b in self.edges if a == i} | {a for a, b in self.edges if b == i})
        )

    def tick_group(self, i: int) -> int:
        """0 or 1 from a breadth-first 2-colouring of the follower graph.

        Followers of group 1 tick half a period after group 0: on a bipartite graph (a
        ring of even length) every link then carries data exactly half a period old both
        ways, which keeps each link's two flows alike.  Odd cycles keep the first colour.
        """
        return self._tick_groups()[i]

    def _tick_groups(self) -> tuple[int, ...]:
        colour = {0: 0}
        frontier = [0]
        while frontier:
            a = frontier.pop(0)
            for b in self.neighbours(a):
                if b not in colour:
                    colour[b] = 1 - colour[a]
                    frontier.append(b)
        return tuple(colour.get(i, 0) for i in range(self.n))

    def tick_phase(self, i: int) -> float:
        """Follower i's tick as a fraction of the period, in [0, 1).

        Group 1 (`tick_group`) ticks half a period after group 0, and within a group the
        members spread over that half period instead of all waking at once: a swarm whose
        followers all tick together queues on the cores (ring8 on 2 cores: 1.3 ms one-way
        latency, issue 15).  The members take slots in zig-zag order (0, 2, 4, .., 5, 3, 1),
        so that members next to each other in index order are at most two slots apart and
        every ring link still carries data about half a period old both ways.
        """
        groups = self._tick_groups()
        members = [j for j in range(self.n) if groups[j] == groups[i]]
        m, k = len(members), members.index(i)
        slot = 2 * k if k < (m + 1) // 2 else 2 * (m - 1 - k) + 1
        return 0.5 * groups[i] + 0.5 * slot / m

    def steady_from_s(self) -> float:
        start = self.run.steady_from_s
        return self.run.duration_s / 2.0 if start is None else start

    @property
    def a_min_rad(self) -> float:
        return min(self.pattern.angles_rad)


def ccw_order(points_m: Sequence[Sequence[float]],
              center_m: Sequence[float]) -> tuple[int, ...]:
    """Successor map i -> i+ of points sorted counter-clockwise around `center_m`
    (ties keep index order: Python's sort is stable)."""
    cx, cy = float(center_m[0]), float(center_m[1])
    angles = [math.atan2(float(p[1]) - cy, float(p[0]) - cx) for p in points_m]
    return successor_from_order(sorted(range(len(angles)), key=angles.__getitem__))


def successor_from_order(order: list[int] | tuple[int, ...]) -> tuple[int, ...]:
    """Successor map i -> i+ of followers listed in circular order."""
    succ = [0] * len(order)
    for k, i in enumerate(order):
        succ[i] = order[(k + 1) % len(order)]
    return tuple(succ)


def successor_is_cycle(successor: tuple[int, ...]) -> bool:
    """True when following successors from 0 visits every follower once."""
    seen, i = set(), 0
    for _ in successor:
        seen.add(i)
        i = successor[i]
    return i == 0 and len(seen) == len(successor)


def full_turn_ok(angles_rad: tuple[float, ...]) -> bool:
    return abs(sum(angles_rad) - 2.0 * math.pi) <= 1e-6


def adjacency_matrix(n: int, edges: Iterable[tuple[int, int]]) -> FloatArray:
    """(n, n) symmetric 0/1 adjacency of undirected `edges`; numpy imported here only (a
    follower process forms its ring without it)."""
    import numpy as np

    adj = np.zeros((n, n))
    for i, j in edges:
        adj[i, j] = adj[j, i] = 1.0
    return adj
