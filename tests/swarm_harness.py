"""The networked follower logic in lock-step, with per-link delay and seeded message loss.

Every follower runs `follower_tick` at a fixed rate on what it has received: each
directed link delivers the state its sender published `delay_ticks` ticks ago,
or loses it with probability `loss`.  No clock, no sockets: a fast, exact
stand-in for the network when testing estimator properties.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from agents.core.profiles import TargetMotion
from agents.core.timeseries import RunSeries
from agents.follower_logic import (
    FollowerMemory,
    FollowerSetup,
    PeerView,
    Sample,
    follower_tick,
    link_flows,
    observe_target,
    ready,
)
from agents.scenario.model import Scenario
from transport.network_schema import NetworkConfig

# r, pos, flow towards each neighbour, and (estimator order 2) rv and velocity flows
Published = tuple[Sample, Sample, dict[int, Sample], Sample, dict[int, Sample]]


def with_estimator(scenario: Scenario, estimator: str) -> Scenario:
    """`paper` or `robust` (the paper's first-order law), or `robust2`: the robust estimator
    with its velocity stage (estimator order 2)."""
    order = 2 if estimator == "robust2" else 1
    gains = dataclasses.replace(scenario.gains, estimator_order=order)
    return dataclasses.replace(scenario, gains=gains,
                               network=NetworkConfig(estimator=estimator.removesuffix("2")))


def _publish(
    i: int,
    memory: FollowerMemory,
    setup: FollowerSetup,
    r: np.ndarray,
    dr: np.ndarray,
    pos: np.ndarray,
    vel: np.ndarray,
    t: float,
) -> Published:
    flows, vel_flows = (
        {j: Sample(np.array([sx, sy]), np.array([fx, fy]), t)
         for j, sx, sy, fx, fy in link_flows(memory, setup, velocity)}
        for velocity in (False, True)
    )
    rv = Sample(memory.rv_m_s.copy(), np.zeros(2), t)
    return Sample(r.copy(), dr.copy(), t), Sample(pos.copy(), vel.copy(), t), flows, rv, vel_flows


Mail = dict[int, list[tuple[int, int, Published]]]  # tick -> (receiver, sender, message)


def run_swarm(
    scenario: Scenario,
    duration_s: float,
    rate_hz: float = 50.0,
    delay_ticks: int = 1,
    loss: float = 0.0,
    seed: int = 0,
    jitter_ticks: int = 0,
    vehicle_tau_s: float = 0.0,
) -> RunSeries:
    """`jitter_ticks`: each message is late by a further 0..jitter_ticks ticks, at random;
    `vehicle_tau_s`: vehicles follow their commands with this first-order lag, as the
    simulator's do (sim_backend.model), instead of at once."""
    dt, n = 1.0 / rate_hz, scenario.n
    rng = np.random.default_rng(seed)
    setups = [FollowerSetup.from_scenario(scenario, i) for i in range(n)]
    memories = [FollowerMemory() for _ in range(n)]
    views: list[dict[int, PeerView]] = [{} for _ in range(n)]
    pos = np.asarray(scenario.follower_pos_m, float)
    vel = np.zeros_like(pos)
    motion = TargetMotion(scenario)
    mail: Mail = {}
    rows: list[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    for k in range(round(duration_s * rate_hz) + 1):
        t = k * dt
        targets, _ = motion.state(t)
        _deliver(mail.pop(k, []), views)
        r_now, dr_now, u_now = np.zeros_like(pos), np.zeros_like(pos), np.zeros_like(pos)
        for i, setup in enumerate(setups):
            for j in setup.observed:
                memories[i] = observe_target(memories[i], setup, j, targets[j], t)
            if ready(memories[i], setup, views[i]):
                own = Sample(pos[i].copy(), vel[i].copy(), t)
                memories[i], out = follower_tick(memories[i], setup, own, views[i], t)
                r_now[i], dr_now[i], u_now[i] = out.r_m, out.dr_m_s, out.u_m_s
            else:
                r_now[i] = setup.weights @ targets
            msg = _publish(i, memories[i], setup, r_now[i], dr_now[i], pos[i], vel[i], t)
            _post(mail, k, i, msg, setups, (delay_ticks, jitter_ticks, loss), rng)
        rows.append((t, pos.copy(), r_now, u_now, targets))
        if vehicle_tau_s <= 0.0:
            vel = u_now
            pos = pos + dt * u_now
        else:
            new_vel = vel + (1.0 - np.exp(-dt / vehicle_tau_s)) * (u_now - vel)
            pos = pos + 0.5 * dt * (vel + new_vel)
            vel = new_vel
    t_s, p, r, u, tg = (np.array(x) for x in zip(*rows, strict=True))
    return RunSeries(t_s, p, r, u, tg)


def _post(
    mail: Mail,
    k: int,
    sender: int,
    msg: Published,
    setups: list[FollowerSetup],
    link: tuple[int, int, float],
    rng: np.random.Generator,
) -> None:
    """Queue `msg` to everyone who listens to `sender`, each copy lost or late at random."""
    delay, jitter, loss = link
    for i, setup in enumerate(setups):
        if sender not in set(setup.neighbours) | {setup.successor}:
            continue
        late = int(rng.integers(0, jitter + 1)) if jitter else 0
        if loss > 0.0 and rng.random() < loss:
            continue
        mail.setdefault(k + delay + late, []).append((i, sender, msg))


def _deliver(arrivals: list[tuple[int, int, Published]], views: list[dict[int, PeerView]]) -> None:
    for receiver, sender, (r, pos, flows, rv, vel_flows) in arrivals:
        known = views[receiver].get(sender)
        if known is None or r.stamp_s > known.r.stamp_s:  # a late old message loses
            views[receiver][sender] = PeerView(r, pos, flows.get(receiver), rv,
                                               vel_flows.get(receiver))
