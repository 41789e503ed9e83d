"""The networked follower's law in lock-step, with per-link delay and seeded message loss.

Every follower runs its law at a fixed rate through the platform's own pieces
(agents.follower: `Latest` keeps its inputs, `LawRunner` runs the law, `stand_ins` fills
links not heard yet) on what it has received: each directed link delivers the
FollowerState its sender published `delay_ticks` ticks ago, or loses it with probability
`loss`.  No clock, no sockets, no codec: a fast, exact stand-in for the network when
testing estimator properties.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from agents.analysis.timeseries import RunSeries
from agents.follower.inputs import Latest
from agents.follower.runner import LawRunner
from agents.law.interface import Law, Sample
from agents.law.paper import PaperLaw
from agents.membership.follower_place import setup_for, stand_ins
from agents.scenario.model import Scenario
from agents.scenario.target_motion import TargetMotion
from transport.law_fields import NO_FIELDS
from transport.messages import FollowerState, Header
from transport.network_schema import NetworkConfig


def with_estimator(scenario: Scenario, estimator: str) -> Scenario:
    """`paper` or `robust` (the paper's first-order law), or `robust2`: the robust estimator
    with its velocity stage (estimator order 2)."""
    order = 2 if estimator == "robust2" else 1
    gains = dataclasses.replace(scenario.gains, estimator_order=order)
    return dataclasses.replace(scenario, gains=gains,
                               network=NetworkConfig(estimator=estimator.removesuffix("2")))


Mail = dict[int, list[tuple[int, FollowerState]]]  # tick -> (receiver, message)


def _xy(v: complex) -> tuple[float, float]:
    return (float(v.real), float(v.imag))


def run_swarm(
    scenario: Scenario,
    duration_s: float,
    rate_hz: float = 50.0,
    delay_ticks: int = 1,
    loss: float = 0.0,
    seed: int = 0,
    jitter_ticks: int = 0,
    vehicle_tau_s: float = 0.0,
    law: Law[Any] | None = None,
) -> RunSeries:
    """`jitter_ticks`: each message is late by a further 0..jitter_ticks ticks, at random;
    `vehicle_tau_s`: vehicles follow their commands with this first-order lag, as the
    simulator's do (sim_backend.kinematics), instead of at once; `law`: the paper's by default."""
    dt, n = 1.0 / rate_hz, scenario.n
    rng = np.random.default_rng(seed)
    law = law or PaperLaw.from_params({}, scenario)
    runners = [LawRunner(law, setup_for(scenario, i)) for i in range(n)]
    latest = [Latest(i, runners[i].declared) for i in range(n)]
    pos = np.asarray(scenario.follower_pos_m, float)
    vel = np.zeros_like(pos)
    motion = TargetMotion(scenario)
    mail: Mail = {}
    rows: list[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    for k in range(round(duration_s * rate_hz) + 1):
        t = k * dt
        targets, _ = motion.state(t)
        for receiver, msg in mail.pop(k, []):
            latest[receiver].receive(msg, t)
        r_now, dr_now, u_now = np.zeros_like(pos), np.zeros_like(pos), np.zeros_like(pos)
        for i, (runner, inputs) in enumerate(zip(runners, latest, strict=True)):
            setup = runner.setup
            for j in setup.observed:
                inputs.observe(setup, j, complex(*targets[j]), t)
            stepped = None
            if runner.last_r is not None or inputs.ready(setup):
                own = Sample(complex(*pos[i]), complex(*vel[i]), t)
                peers = stand_ins(inputs.peers, setup, runner.last_r, t)
                stepped = runner.step(t, True, own, inputs.targets, peers)
            if stepped is None:
                r, dr, u, fields = runner.standing_estimate(inputs.targets, t), 0j, 0j, NO_FIELDS
            else:
                out, fields = stepped
                r, dr, u = out.r_m, out.dr_m_s, out.u_m_s
            r_now[i], dr_now[i], u_now[i] = _xy(r), _xy(dr), _xy(u)
            msg = FollowerState(Header(f"follower-{i}", k, t), i, _xy(r), _xy(dr),
                                _xy(complex(*pos[i])), _xy(complex(*vel[i])), _xy(u), t, fields)
            _post(mail, k, i, msg, runners, (delay_ticks, jitter_ticks, loss), rng)
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
    msg: FollowerState,
    runners: list[LawRunner],
    link: tuple[int, int, float],
    rng: np.random.Generator,
) -> None:
    """Queue `msg` to everyone who listens to `sender`, each copy lost or late at random."""
    delay, jitter, loss = link
    for i, runner in enumerate(runners):
        if sender not in runner.setup.peers:
            continue
        late = int(rng.integers(0, jitter + 1)) if jitter else 0
        if loss > 0.0 and rng.random() < loss:
            continue
        mail.setdefault(k + delay + late, []).append((i, msg))
