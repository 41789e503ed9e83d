"""The fast follower's state (agents.follower_fast): follower_logic's types with plane
vectors as complex x + iy, and the constants the fast path derives from a setup once.
Split from follower_fast, which re-exports every name."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import NamedTuple

from agents.follower_setup import FollowerSetup
from agents.scenario.model import Scenario


class Sample(NamedTuple):
    """A timestamped position (or estimate) x + iy with its rate (follower_logic.Sample)."""

    value: complex
    rate: complex
    stamp_s: float

    def at(self, t_s: float) -> complex:
        return self.value + self.rate * (t_s - self.stamp_s)

    def held(self, t_s: float, limit_s: float) -> complex:
        return self.value + self.rate * (min(t_s, self.stamp_s + limit_s) - self.stamp_s)

    def held_rate(self, t_s: float, limit_s: float) -> complex:
        return self.rate if t_s - self.stamp_s <= limit_s else 0j


class TargetTrack(NamedTuple):
    """follower_memory.TargetTrack, vectors as complex: a Sample and its velocity filter."""

    value: complex
    rate: complex
    stamp_s: float
    smooth: complex = 0j
    accel: complex = 0j
    primed: bool = False


_NO_AGES: Mapping[int, float] = MappingProxyType({})
_NO_TRACKS: Mapping[int, TargetTrack] = MappingProxyType({})


class PeerView(NamedTuple):
    r: Sample
    pos: Sample
    flow: Sample | None = None
    rv: complex | None = None  # order 2: its estimate of the targets' mean velocity
    vel_flow: Sample | None = None  # order 2: its velocity stage's sum and rate towards us


class FollowerMemory(NamedTuple):
    """follower_logic.FollowerMemory, vectors as complex; immutable (never mutate its maps)."""

    phi_m: complex = 0j
    phi_rate_m_s: complex = 0j
    last_tick_s: float | None = None
    peer_age_s: Mapping[int, float] = _NO_AGES
    targets: Mapping[int, TargetTrack] = _NO_TRACKS
    link_sums_m: tuple[complex, ...] | None = None
    link_rates_m_s: tuple[complex, ...] | None = None
    last_r: Sample | None = None
    carry_m: complex = 0j
    rebase_pending: bool = False
    vel_sums_m_s: tuple[complex, ...] | None = None
    vel_rates_m_s2: tuple[complex, ...] | None = None
    rv_m_s: complex = 0j


class TickOutput(NamedTuple):
    u_m_s: complex
    r_m: complex
    dr_m_s: complex
    z_m: float
    delta: float
    stale: tuple[str, ...]


@dataclass(frozen=True)
class FastSetup:
    """A FollowerSetup (`ref`) and the constants the fast path derives from it once."""

    ref: FollowerSetup
    index: int
    neighbours: tuple[int, ...]
    successor: int
    observed: tuple[int, ...]
    angle_rad: float
    est_period_s: float
    robust: bool
    second_order: bool  # the velocity stage (estimator order 2)
    hold_s: float  # ref.hold_after_s
    stale_s: float  # ref.stale_after_s
    peers: tuple[int, ...]  # neighbours and successor, sorted
    weights: tuple[tuple[int, float], ...]  # (target, weight) per observed target
    nbr_steps: tuple[tuple[int, float], ...]  # (neighbour, edge fraction * estimator step)
    rotation: complex  # e^(i angle): a missing successor stands where it should be
    target_names: tuple[tuple[int, str], ...]
    peer_names: tuple[tuple[int, str], ...]

    @staticmethod
    def of(setup: FollowerSetup) -> FastSetup:
        peers = tuple(sorted(set(setup.neighbours) | {setup.successor}))
        step = setup.est_period_s
        return FastSetup(
            setup, setup.index, setup.neighbours, setup.successor, setup.observed,
            setup.angle_rad, step, setup.robust,
            setup.robust and setup.estimator.order == 2, setup.hold_after_s,
            setup.stale_after_s, peers,
            tuple((j, float(setup.weights[j])) for j in setup.observed),
            tuple((j, float(f) * step)
                  for j, f in zip(setup.neighbours, setup.nbr_fractions, strict=True)),
            complex(math.cos(setup.angle_rad), math.sin(setup.angle_rad)),
            tuple((j, f"target{j}") for j in setup.observed),
            tuple((j, f"follower{j}") for j in peers),
        )

    @staticmethod
    def from_scenario(scenario: Scenario, index: int,
                      members: Iterable[int] | None = None) -> FastSetup:
        return FastSetup.of(FollowerSetup.from_scenario(scenario, index, members))
