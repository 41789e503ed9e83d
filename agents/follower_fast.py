"""The networked follower's estimator and controller, cheap: a twin of agents.follower_logic.

The same functions with the same arguments and the same laws, step for step, with plane
vectors as complex numbers x + iy instead of (2,) arrays, and per-setup constants worked
out once (`FastSetup`).  At 2-vectors numpy's per-call cost was most of a step's (issue 15:
ring16's followers run ~200 estimator steps a second each, 16 on 2 cores).  The laws
themselves are agents.law's (the lock-step engine compiles the same functions) and
agents.estimate_carry.next_carry_c; tests/unit/test_follower_fast.py pins every function
here to follower_logic's over random inputs and sequences of steps.  agents.follower_logic
stays the reference (and is what the lock-step harness tests/swarm_harness.py drives);
agents.follower runs this one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

from agents.estimate_carry import REBASE_TAU_S, next_carry_c

# The types live beside it; importers keep finding them here.
from agents.follower_fast_memory import FastSetup as FastSetup
from agents.follower_fast_memory import FollowerMemory as FollowerMemory
from agents.follower_fast_memory import PeerView as PeerView
from agents.follower_fast_memory import Sample as Sample
from agents.follower_fast_memory import TargetTrack as TargetTrack
from agents.follower_fast_memory import TickOutput as TickOutput
from agents.law.consensus import consensus_flows, link_balance
from agents.law.enclosing import enclosing_control
from agents.law.sig import rate_cap
from agents.law.target_velocity import finite_difference_velocity, lag_free_velocity
from agents.law.velocity_stage import fed_flow, lap_velocity

if TYPE_CHECKING:
    from transport.messages import FollowerState


# A NamedTuple built without its Python-level __new__: half the cost, same object.
_new = tuple.__new__


def peer_view(msg: FollowerState, receiver: int) -> PeerView:
    """What `receiver` keeps of a neighbour's state (its robust link sum towards `receiver`)."""
    stamp = msg.header.stamp_s
    return _new(PeerView, (_new(Sample, (complex(*msg.r_m), complex(*msg.dr_m_s), stamp)),
                           _new(Sample, (complex(*msg.pos_m), complex(*msg.vel_m_s),
                                         msg.vehicle_stamp_s)),
                           _towards(msg.link_flows, receiver, stamp), complex(*msg.rv_m_s),
                           _towards(msg.rv_flows, receiver, stamp)))


def _towards(flows: tuple[tuple[int, float, float, float, float], ...], receiver: int,
             stamp_s: float) -> Sample | None:
    """The published link flow on the link to `receiver`, as a Sample (None: not there)."""
    for f in flows:
        if f[0] == receiver:
            return _new(Sample, (complex(f[1], f[2]), complex(f[3], f[4]), stamp_s))
    return None


def observe_target(
    memory: FollowerMemory, setup: FastSetup, target: int, pos_m: complex, stamp_s: float
) -> FollowerMemory:
    """Fold one observation in (follower_logic.observe_target)."""
    if target not in setup.observed:
        return memory
    prev = memory.targets.get(target)
    if prev is None:
        track = _new(TargetTrack, (pos_m, 0j, stamp_s, 0j, 0j, False))
    elif stamp_s <= prev.stamp_s:
        return memory  # duplicate or reordered: the newer sample stands
    else:
        if not prev.primed:
            raw = finite_difference_velocity(prev.value, prev.stamp_s, pos_m, stamp_s, 0j)
            track = _new(TargetTrack, (pos_m, raw, stamp_s, raw, 0j, True))
        else:
            ref = setup.ref
            vel, smooth, accel = lag_free_velocity(
                prev.value, prev.stamp_s, pos_m, stamp_s, prev.smooth, prev.accel,
                ref.target_vel_tau_s, ref.target_accel_tau_s)
            track = _new(TargetTrack, (pos_m, vel, stamp_s, smooth, accel, True))
    m = memory
    return _new(FollowerMemory, (m.phi_m, m.phi_rate_m_s, m.last_tick_s, m.peer_age_s,
                                 {**m.targets, target: track}, m.link_sums_m, m.link_rates_m_s,
                                 m.last_r, m.carry_m, m.rebase_pending, m.vel_sums_m_s,
                                 m.vel_rates_m_s2, m.rv_m_s))


def ready(memory: FollowerMemory, setup: FastSetup, peers: Mapping[int, PeerView]) -> bool:
    """True once every observed target and every neighbour and the successor was heard."""
    targets = memory.targets
    return all(j in targets for j in setup.observed) and all(j in peers for j in setup.peers)


def reference(memory: FollowerMemory, setup: FastSetup, now_s: float) -> tuple[complex, complex]:
    """p~_i and its rate at now_s (targets not heard yet count as zero)."""
    p, rate, hold = 0j, 0j, setup.hold_s
    targets = memory.targets
    for j, w in setup.weights:
        track = targets.get(j)
        if track is not None:
            value, track_rate, stamp = track.value, track.rate, track.stamp_s
            p += w * (value + track_rate * (min(now_s, stamp + hold) - stamp))
            if now_s - stamp <= hold:
                rate += w * track_rate
    return p, rate


def _stale(memory: FollowerMemory, setup: FastSetup, peers: Mapping[int, PeerView],
           now_s: float) -> tuple[str, ...]:
    limit, targets = setup.stale_s, memory.targets
    old = [name for j, name in setup.target_names
           if j not in targets or now_s - targets[j].stamp_s > limit]
    old += [name for j, name in setup.peer_names if now_s - peers[j].r.stamp_s > limit]
    return tuple(old)


def _ages(memory: FollowerMemory, setup: FastSetup, peers: Mapping[int, PeerView],
          now_s: float, dt: float) -> dict[int, float]:
    gain = 1.0 - math.exp(-dt / setup.ref.age_tau_s)
    ages = dict(memory.peer_age_s)
    limit = setup.stale_s
    for j in setup.peers:
        age = min(now_s - peers[j].r.stamp_s, limit)
        old = ages.get(j)
        ages[j] = age if old is None else old + gain * (age - old)
    return ages


Links = tuple[list[complex], list[float], list[bool], list[complex], list[complex]]


def _links(setup: FastSetup, peers: Mapping[int, PeerView], now_s: float,
           ages: Mapping[int, float]) -> Links:
    """Per neighbour: r_j carried to now_s, the step-limited edge fraction (it shrinks with
    the age of the data), whether it is live, and (robust) its link sum and rate towards us."""
    hold, limit, step = setup.hold_s, setup.stale_s, setup.est_period_s
    r_nbrs, fractions, live, sums, rates = [], [], [], [], []
    for j, f_step in setup.nbr_steps:
        view = peers[j]
        value, rate, stamp = view.r
        r_nbrs.append(value + rate * (min(now_s, stamp + hold) - stamp))
        fractions.append(f_step / max(ages[j], step))
        live.append(now_s - stamp <= limit)
        flow = view.flow
        if flow is None:
            sums.append(0j)
            rates.append(0j)
        else:
            value, rate, stamp = flow
            sums.append(value + rate * (min(now_s, stamp + hold) - stamp))
            rates.append(rate if now_s - stamp <= hold else 0j)
    return r_nbrs, fractions, live, sums, rates


def _advance(memory: FollowerMemory, setup: FastSetup, peers: Mapping[int, PeerView],
             now_s: float) -> tuple[FollowerMemory, complex, complex]:
    """The estimator over the time since its last step: new memory, r_i, dr_i/dt
    (follower_logic._advance and _estimate in one)."""
    last = memory.last_tick_s
    dt = 0.0 if last is None else min(max(now_s - last, 0.0), setup.ref.max_gap_s)
    ages = _ages(memory, setup, peers, now_s, dt)
    p_tilde, p_tilde_rate = reference(memory, setup, now_s)
    r_nbrs, fractions, live, their_sums, their_rates = _links(setup, peers, now_s, ages)
    resume = None
    if memory.rebase_pending and memory.last_r is not None:
        resume = memory.last_r.held(now_s, setup.hold_s)
    sums, rates = memory.link_sums_m, memory.link_rates_m_s
    if setup.robust:
        zeros = (0j,) * len(r_nbrs)
        sums = tuple([s + dt * f for s, f in zip(sums or zeros, rates or zeros, strict=True)])
        phi = link_balance(sums, their_sums)
    else:
        phi = memory.phi_m + dt * memory.phi_rate_m_s
    carry = next_carry_c(memory.carry_m, phi + p_tilde, resume, dt)
    est = setup.ref.estimator
    flows = consensus_flows(phi + p_tilde + carry, r_nbrs, fractions, est.k_e, 1.0 / est.alpha1,
                            rate_cap(est.step_fraction, setup.est_period_s))
    if not all(live):
        flows = [f if ok else 0j for f, ok in zip(flows, live, strict=True)]
    vel_sums, vel_rates, rv = memory.vel_sums_m_s, memory.vel_rates_m_s2, memory.rv_m_s
    if setup.second_order:
        vel_sums, vel_rates, rv = _velocity_stage(memory, setup, peers, now_s, dt,
                                                  p_tilde_rate, live, fractions)
        flows = [fed_flow(f, s) if ok else 0j
                 for f, s, ok in zip(flows, vel_sums, live, strict=True)]
    if setup.robust:
        phi_rate = link_balance(flows, their_rates)
        rates = tuple(flows)
    else:
        phi_rate = sum(flows, 0j)
    r = phi + p_tilde + carry
    dr = phi_rate + p_tilde_rate - carry / REBASE_TAU_S
    # A target newly ours is not heard yet: p~_i lacks it, so r_i stays carried until it is.
    pending = memory.rebase_pending and not all(j in memory.targets for j in setup.observed)
    new = _new(FollowerMemory, (phi, phi_rate, now_s, ages, memory.targets, sums, rates,
                                _new(Sample, (r, dr, now_s)), carry, pending, vel_sums,
                                vel_rates, rv))
    return new, r, dr


Stage = tuple[tuple[complex, ...], tuple[complex, ...], complex]


def _velocity_stage(memory: FollowerMemory, setup: FastSetup, peers: Mapping[int, PeerView],
                    now_s: float, dt: float, p_tilde_rate: complex, live: list[bool],
                    fractions: list[float]) -> Stage:
    """Order 2 (follower_logic._velocity_stage): its link sums, new flows, and rv_i."""
    zeros = (0j,) * len(live)
    sums = tuple([s + dt * f for s, f in zip(memory.vel_sums_m_s or zeros,
                                             memory.vel_rates_m_s2 or zeros, strict=True)])
    hold, theirs, rv_nbrs = setup.hold_s, [], []
    for j, _ in setup.nbr_steps:
        view = peers[j]
        flow = view.vel_flow
        if flow is None:
            theirs.append(0j)
        else:
            value, rate, stamp = flow
            theirs.append(value + rate * (min(now_s, stamp + hold) - stamp))
        rv_nbrs.append(view.rv)
    rv = lap_velocity(link_balance(sums, theirs), p_tilde_rate)
    est = setup.ref.estimator
    flows = consensus_flows(rv, [rv if v is None else v for v in rv_nbrs], fractions, est.k_e,
                            1.0 / est.alpha1, rate_cap(est.step_fraction, setup.est_period_s))
    return sums, tuple([f if ok else 0j for f, ok in zip(flows, live, strict=True)]), rv


def estimator_tick(memory: FollowerMemory, setup: FastSetup, peers: Mapping[int, PeerView],
                   now_s: float) -> FollowerMemory:
    """One estimator step at `now_s` between control ticks (follower_logic.estimator_tick)."""
    return _advance(memory, setup, peers, now_s)[0]


def follower_tick(memory: FollowerMemory, setup: FastSetup, own: Sample,
                  peers: Mapping[int, PeerView], now_s: float) -> tuple[FollowerMemory, TickOutput]:
    """One control cycle at `now_s` (follower_logic.follower_tick)."""
    ref = setup.ref
    new_memory, r, dr = _advance(memory, setup, peers, now_s)
    lead = ref.lead_s
    at_s = now_s + lead
    own_pos = own.held(at_s, ref.hold_after_s)
    r_at = r + dr * lead
    succ = peers[setup.successor].pos
    if now_s - succ.stamp_s <= ref.stale_after_s:
        succ_pos = succ.value + succ.rate * (at_s - succ.stamp_s)
    else:  # missing: where it should be, so that only radius and rotation act
        succ_pos = r_at + (own_pos - r_at) * setup.rotation
    c = ref.control
    try:
        u, z, delta = enclosing_control(
            own_pos, succ_pos, r_at, dr, setup.angle_rad, c.k_z, 1.0 / c.alpha2, c.k_d,
            1.0 / c.alpha3, c.rho_d_m, c.w_d_rad_s, c.step_fraction, c.spacing_gain_age,
            ref.period_s, new_memory.peer_age_s[setup.successor])
    except ArithmeticError:  # numpy's inf where Python raises (|x| past 1e308)
        u, z, delta = 0j, math.nan, math.nan
    if not (math.isfinite(u.real) and math.isfinite(u.imag) and math.isfinite(z)):
        u = 0j  # never fly a NaN: hold, and let the caller count it
    return new_memory, _new(TickOutput, (u, r, dr, z, delta, _stale(memory, setup, peers, now_s)))


def link_flows(memory: FollowerMemory, setup: FastSetup, velocity: bool = False,
               ) -> tuple[tuple[int, float, float, float, float], ...]:
    """What the robust estimator publishes: (j, sum x, y, rate x, y) per neighbour
    (`velocity`: its velocity stage's, order 2)."""
    sums, rates = memory.link_sums_m, memory.link_rates_m_s
    if velocity:
        sums, rates = memory.vel_sums_m_s, memory.vel_rates_m_s2
    if sums is None or rates is None:
        return ()
    return tuple([(j, s.real, s.imag, f.real, f.imag)
                  for j, s, f in zip(setup.neighbours, sums, rates, strict=True)])

