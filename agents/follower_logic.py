"""One follower's estimator and controller on asynchronous, timestamped data: pure.

The networked follower sees the world as the latest timestamped samples: its own
vehicle state, observations of the targets it watches, and the states its
neighbours and its successor published.  `follower_tick` extrapolates every input
to `now_s` with its own rate (first order), integrates the estimator over the
measured time since the previous tick (at most `max_gap_s`), and returns the
command.  It holds no clock and does no I/O; time is an argument.

Inputs are not extrapolated for seconds.  Positions, estimates and link sums are
carried at most `hold_after_s` past their stamp, then held: a stall of the data
(a scheduling hiccup, a simulator catching up) is bridged by extrapolation, which
is exact for a vehicle flying its last setpoint, while a long silence does not fly
the swarm on a guess.  A neighbour or successor older than `stale_after_s` (the
vehicle link timeout) is missing: its link carries no flow (neither end integrates
on it, so a link's two flows still cancel for the paper's estimator; the robust one
keeps the neighbour's link sum as last known), and a missing successor drops the
spacing term (radius and rotation go on, as if it were where it should be) instead
of chasing a stale bearing.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from agents.core.controller import enclosing_control
from agents.core.estimator import consensus_flows, link_balance
from agents.estimate_carry import REBASE_TAU_S, next_carry

# The types live beside it; importers keep finding them here.
from agents.follower_memory import ZERO2 as ZERO2
from agents.follower_memory import FloatArray as FloatArray
from agents.follower_memory import FollowerMemory as FollowerMemory
from agents.follower_memory import PeerView as PeerView
from agents.follower_memory import Sample as Sample
from agents.follower_memory import TargetTrack as TargetTrack
from agents.follower_memory import TickOutput as TickOutput

# Its weights and edge fractions are tuples: the follower process builds one too, without
# numpy (agents.follower_fast); this module makes arrays of them where it computes.
from agents.follower_setup import FollowerSetup as FollowerSetup
from agents.law.consensus import EstimatorParams
from agents.law.target_velocity import finite_difference_velocity, lag_free_velocity

if TYPE_CHECKING:
    from transport.messages import FollowerState


def peer_view(msg: FollowerState, receiver: int) -> PeerView:
    """What `receiver` keeps of a neighbour's state (its robust link sum towards `receiver`)."""
    stamp = msg.header.stamp_s

    def towards_us(flows: tuple[tuple[int, float, float, float, float], ...]) -> Sample | None:
        return next((Sample(np.array(f[1:3]), np.array(f[3:5]), stamp)
                     for f in flows if f[0] == receiver), None)

    return PeerView(
        Sample(np.asarray(msg.r_m), np.asarray(msg.dr_m_s), stamp),
        Sample(np.asarray(msg.pos_m), np.asarray(msg.vel_m_s), msg.vehicle_stamp_s),
        towards_us(msg.link_flows),
        Sample(np.asarray(msg.rv_m_s), ZERO2, stamp),
        towards_us(msg.rv_flows),
    )


def observe_target(
    memory: FollowerMemory, setup: FollowerSetup, target: int, pos_m: FloatArray, stamp_s: float
) -> FollowerMemory:
    """Fold one observation in: position, and velocity by finite difference, low-passed
    and corrected for the lag that costs (agents.law.target_velocity.lag_free_velocity)."""
    if target not in setup.observed:
        return memory
    prev = memory.targets.get(target)
    pos = np.asarray(pos_m, float)
    if prev is None:
        track = TargetTrack(pos, ZERO2, stamp_s)
    elif stamp_s <= prev.stamp_s:
        return memory  # duplicate or reordered: the newer sample stands
    else:
        if not prev.primed:  # the first velocity: nothing to smooth it against yet
            raw = finite_difference_velocity(prev.value, prev.stamp_s, pos, stamp_s, ZERO2)
            track = TargetTrack(pos, raw, stamp_s, raw, ZERO2, True)
        else:
            vel, smooth, accel = lag_free_velocity(
                prev.value, prev.stamp_s, pos, stamp_s, prev.smooth_m_s, prev.accel_m_s2,
                setup.target_vel_tau_s, setup.target_accel_tau_s)
            track = TargetTrack(pos, vel, stamp_s, smooth, accel, True)
    return replace(memory, targets={**memory.targets, target: track})


def ready(memory: FollowerMemory, setup: FollowerSetup, peers: dict[int, PeerView]) -> bool:
    """True once every observed target and every neighbour and the successor was heard."""
    needed = set(setup.neighbours) | {setup.successor}
    return all(j in memory.targets for j in setup.observed) and needed <= peers.keys()


def _stale(
    memory: FollowerMemory, setup: FollowerSetup, peers: dict[int, PeerView], now_s: float
) -> tuple[str, ...]:
    old = [
        f"target{j}"
        for j in setup.observed  # a target newly ours may not be heard yet: missing
        if j not in memory.targets or now_s - memory.targets[j].stamp_s > setup.stale_after_s
    ]
    for j in sorted(set(setup.neighbours) | {setup.successor}):
        if now_s - peers[j].r.stamp_s > setup.stale_after_s:
            old.append(f"follower{j}")
    return tuple(old)


def reference(
    memory: FollowerMemory, setup: FollowerSetup, now_s: float
) -> tuple[FloatArray, FloatArray]:
    """p~_i and its rate at now_s, from the observed targets' tracks (targets not heard
    yet count as zero: the estimate a follower publishes before it is `ready`)."""
    heard = [j for j in setup.observed if j in memory.targets]
    w = [setup.weights[j] for j in heard]
    tracks = [memory.targets[j] for j in heard]
    limit = setup.hold_after_s
    p_tilde = sum((wj * s.held(now_s, limit) for wj, s in zip(w, tracks, strict=True)), ZERO2)
    rate = sum((wj * s.held_rate(now_s, limit) for wj, s in zip(w, tracks, strict=True)), ZERO2)
    return np.asarray(p_tilde), np.asarray(rate)


def _their_flows(
    setup: FollowerSetup, peers: dict[int, PeerView], now_s: float, velocity: bool = False
) -> tuple[FloatArray, FloatArray]:
    """(d, 2) each neighbour's running sum on its link to us, carried to now_s, and its rate
    (`velocity`: its velocity stage's)."""
    sums, rates = np.zeros((len(setup.neighbours), 2)), np.zeros((len(setup.neighbours), 2))
    limit = setup.hold_after_s
    for k, j in enumerate(setup.neighbours):
        flow = peers[j].vel_flow if velocity else peers[j].flow
        if flow is not None:
            sums[k], rates[k] = flow.held(now_s, limit), flow.held_rate(now_s, limit)
    return sums, rates


def _estimate(
    memory: FollowerMemory,
    setup: FollowerSetup,
    peers: dict[int, PeerView],
    now_s: float,
    dt: float,
    peer_age_s: dict[int, float],
) -> tuple[dict[str, object], FloatArray, FloatArray]:
    """The memory's new fields, r_i and dr_i/dt at now_s, with the paper's or the robust
    estimator (fields, not a new memory: one `replace` per step is a fifth of its cost)."""
    p_tilde, p_tilde_rate = reference(memory, setup, now_s)
    hold, limit = setup.hold_after_s, setup.stale_after_s
    r_nbrs = np.array([peers[j].r.held(now_s, hold) for j in setup.neighbours]).reshape(-1, 2)
    live = np.array([peers[j].r.fresh(now_s, limit) for j in setup.neighbours], float)[:, None]
    # Both estimators: a link's flow may remove at most step_fraction of the gap per age
    # of the data it acts on (not per tick), so that late or lost data slow the
    # consensus down instead of making it ring.  Neither law changes; the discretisation
    # stays consistent (fresh data: the lock-step limit).
    ages = np.array([peer_age_s[j] for j in setup.neighbours])
    step = setup.est_period_s
    fractions = np.asarray(setup.nbr_fractions) * step / np.maximum(ages, step)
    args = (fractions, setup.estimator, step)
    resume = None
    if memory.rebase_pending and memory.last_r is not None:
        resume = memory.last_r.held(now_s, setup.hold_after_s)
    tau = REBASE_TAU_S
    if not setup.robust:
        phi = memory.phi_m + dt * memory.phi_rate_m_s
        carry = next_carry(memory.carry_m, phi + p_tilde, resume, dt)
        phi_rate = (live * consensus_flows(phi + p_tilde + carry, r_nbrs, *args)).sum(axis=0)
        paper = {"phi_m": phi, "phi_rate_m_s": phi_rate, "carry_m": carry}
        return paper, phi + p_tilde + carry, phi_rate + p_tilde_rate - carry / tau
    d = len(setup.neighbours)
    sums = np.zeros((d, 2)) if memory.link_sums_m is None else memory.link_sums_m
    rates = np.zeros((d, 2)) if memory.link_rates_m_s is None else memory.link_rates_m_s
    sums = sums + dt * rates
    their_sums, their_rates = _their_flows(setup, peers, now_s)
    phi = link_balance(sums, their_sums)
    carry = next_carry(memory.carry_m, phi + p_tilde, resume, dt)
    flows = live * consensus_flows(phi + p_tilde + carry, r_nbrs, *args)
    fields: dict[str, object] = {"link_sums_m": sums, "carry_m": carry}  # robust
    if setup.estimator.order == 2:
        vel_sums, vel_flows, rv = _velocity_stage(memory, setup, peers, now_s, dt, p_tilde_rate,
                                                  live, args)
        fields.update(vel_sums_m_s=vel_sums, vel_rates_m_s2=vel_flows, rv_m_s=rv)
        # Each link's sum also integrates its velocity sum: Phi_i' = consensus + Psi_i,
        # and the link's two ends still balance exactly.
        flows = flows + live * vel_sums
    phi_rate = link_balance(flows, their_rates)
    fields.update(phi_m=phi, phi_rate_m_s=phi_rate, link_rates_m_s=flows)
    return fields, phi + p_tilde + carry, phi_rate + p_tilde_rate - carry / tau


def _velocity_stage(
    memory: FollowerMemory,
    setup: FollowerSetup,
    peers: dict[int, PeerView],
    now_s: float,
    dt: float,
    p_tilde_rate: FloatArray,
    live: FloatArray,
    args: tuple[FloatArray, EstimatorParams, float],
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Order 2: the same robust consensus on rv_i = Psi_i + dp~_i/dt, the targets' mean
    velocity; returns its link sums (Psi_i = their balance), its new flows, and rv_i."""
    d = len(setup.neighbours)
    sums = np.zeros((d, 2)) if memory.vel_sums_m_s is None else memory.vel_sums_m_s
    rates = np.zeros((d, 2)) if memory.vel_rates_m_s2 is None else memory.vel_rates_m_s2
    sums = sums + dt * rates
    their_sums, _ = _their_flows(setup, peers, now_s, velocity=True)
    rv = link_balance(sums, their_sums) + p_tilde_rate
    heard = [peers[j].rv for j in setup.neighbours]
    rv_nbrs = np.array([rv if h is None else h.value for h in heard]).reshape(-1, 2)
    return sums, live * consensus_flows(rv, rv_nbrs, *args), rv


def _smoothed_ages(
    memory: FollowerMemory,
    setup: FollowerSetup,
    peers: dict[int, PeerView],
    now_s: float,
    dt: float,
) -> dict[int, float]:
    gain = 1.0 - math.exp(-dt / setup.age_tau_s)
    ages = dict(memory.peer_age_s)
    for j in set(setup.neighbours) | {setup.successor}:
        # A missing peer's age stops at the limit: its link is off meanwhile, and its step
        # limits must be back to normal soon after it is heard again.
        age = min(now_s - peers[j].r.stamp_s, setup.stale_after_s)
        ages[j] = age if j not in ages else ages[j] + gain * (age - ages[j])
    return ages


def _advance(
    memory: FollowerMemory, setup: FollowerSetup, peers: dict[int, PeerView], now_s: float
) -> tuple[FollowerMemory, FloatArray, FloatArray]:
    """The estimator over the time since its last step: new memory, r_i, dr_i/dt."""
    last = memory.last_tick_s
    dt = 0.0 if last is None else min(max(now_s - last, 0.0), setup.max_gap_s)
    ages = _smoothed_ages(memory, setup, peers, now_s, dt)
    fields, r, dr = _estimate(memory, setup, peers, now_s, dt, ages)
    # A target newly ours is not heard yet: p~_i lacks it, so r_i stays carried until it is.
    pending = memory.rebase_pending and not all(j in memory.targets for j in setup.observed)
    new_memory = replace(memory, **fields, peer_age_s=ages, last_tick_s=now_s,  # type: ignore[arg-type]
                         last_r=Sample(r, dr, now_s), rebase_pending=pending)
    return new_memory, r, dr


def estimator_tick(
    memory: FollowerMemory, setup: FollowerSetup, peers: dict[int, PeerView], now_s: float
) -> FollowerMemory:
    """One estimator step at `now_s` between control ticks (at `setup.est_period_s`).

    The same integration as the control tick's, which is only one more estimator step
    followed by the control law: a link's flows still cancel (or balance, robust)."""
    return _advance(memory, setup, peers, now_s)[0]


def follower_tick(
    memory: FollowerMemory,
    setup: FollowerSetup,
    own: Sample,
    peers: dict[int, PeerView],
    now_s: float,
) -> tuple[FollowerMemory, TickOutput]:
    """One control cycle at `now_s`; call when `ready`, or after the first cycle with
    the peers not heard yet stood in for (agents.follower_membership.with_missing)."""
    new_memory, r, dr = _advance(memory, setup, peers, now_s)
    at_s = now_s + setup.lead_s  # when the command acts (FollowerSetup.lead_s)
    own_pos = own.held(at_s, setup.hold_after_s)
    r_at = r + dr * setup.lead_s
    succ = peers[setup.successor].pos
    if succ.fresh(now_s, setup.stale_after_s):
        succ_pos = succ.at(at_s)
    else:  # missing: where it should be, so that only radius and rotation act
        rel = complex(*(own_pos - r_at)) * complex(math.cos(setup.angle_rad),
                                                    math.sin(setup.angle_rad))
        succ_pos = r_at + np.array([rel.real, rel.imag])
    out = enclosing_control(
        own_pos[None, :],
        succ_pos[None, :],
        r_at[None, :],
        dr[None, :],
        np.array([setup.angle_rad]),
        setup.control,
        setup.period_s,
        new_memory.peer_age_s[setup.successor],
    )
    u = out.u_m_s[0].copy()
    z, delta = float(out.z_m[0]), float(out.delta[0])
    if not (np.all(np.isfinite(u)) and math.isfinite(z)):
        u = np.zeros(2)  # never fly a NaN: hold, and let the caller count it
    return new_memory, TickOutput(u, r, dr, z, delta, _stale(memory, setup, peers, now_s))


def link_flows(
    memory: FollowerMemory, setup: FollowerSetup, velocity: bool = False
) -> tuple[tuple[int, float, float, float, float], ...]:
    """What the robust estimator publishes: (j, sum x, y, rate x, y) per neighbour
    (`velocity`: its velocity stage's, order 2)."""
    sums, rates = memory.link_sums_m, memory.link_rates_m_s
    if velocity:
        sums, rates = memory.vel_sums_m_s, memory.vel_rates_m_s2
    if sums is None or rates is None:
        return ()
    return tuple(
        (j, float(s[0]), float(s[1]), float(f[0]), float(f[1]))
        for j, s, f in zip(setup.neighbours, sums, rates, strict=True)
    )
