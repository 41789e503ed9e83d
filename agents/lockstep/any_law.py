"""Any law (agents.law.interface) in lock-step: one process, no clock, no network.

The followers' vehicles are single integrators p' = u, as in agents.lockstep.engine; each
follower's law runs through the same pieces as in a follower process: its inputs kept by
agents.follower.inputs (targets through the platform's velocity filter, neighbours'
messages with their declared fields), its steps guarded by agents.follower.runner (a law
that raises or returns a non-finite command holds its vehicle and is counted).

One step of `dt_e` (the estimator's step; the control step `dt` is `substeps` of them):
1. every follower observes its targets, exactly, at the step's time;
2. it receives its neighbours' messages of the PREVIOUS step, stamped then (at the first
   step: what each published before the start, its p~ as its estimate): all followers
   step on the same information, none sees another's output of the same step, as over a
   network whose messages take one step; a law extrapolates them to now by their rates
   (`Sample.held`), which is what makes that lag small;
3. every law steps (`command` on control steps); its output becomes its message;
4. on control steps the commands are recorded and flown for `dt`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from agents.analysis.timeseries import RunSeries
from agents.follower.inputs import Latest
from agents.follower.runner import LawRunner
from agents.law.interface import Law, Sample
from agents.lockstep.engine import estimator_substeps
from agents.membership.follower_place import setup_for, stand_ins
from agents.scenario.model import Scenario
from agents.scenario.target_motion import TargetMotion
from transport.law_fields import NO_FIELDS, LawFields
from transport.messages import FollowerState, Header

ProgressFn = Callable[[float], None]
PROGRESS_EVERY = 100  # control steps


@dataclasses.dataclass
class LawRun:
    """A lock-step run of a law: its series and how often the law failed (held)."""

    series: RunSeries
    law_failures: int


def simulate_law(scenario: Scenario, law: Law[Any], dt_s: float, duration_s: float,
                 progress: ProgressFn | None = None,
                 estimator_dt_s: float | None = None) -> LawRun:
    """`law` flown by every follower of `scenario` for `duration_s` at control step `dt_s`
    (estimator step `estimator_dt_s`, dividing it); every control step is recorded."""
    sub = estimator_substeps(dt_s, estimator_dt_s)
    dt_e = dt_s / sub
    steps = round(duration_s / dt_s)
    fine_t = np.arange(steps * sub + 1, dtype=np.float64) * dt_e
    targets, _ = TargetMotion(scenario, horizon_s=duration_s).states(fine_t)
    swarm = _Swarm(scenario, law, dt_s, dt_e)
    n = scenario.n
    pos = np.empty((steps + 1, n, 2))
    est, cmd = np.empty_like(pos), np.zeros_like(pos)
    vehicles = [complex(x, y) for x, y in scenario.follower_pos_m]
    for k in range(steps + 1):
        pos[k] = [(v.real, v.imag) for v in vehicles]
        for s in range(sub if k < steps else 1):
            e = k * sub + s
            flown = [v + (s * dt_e) * u for v, u in zip(vehicles, swarm.u, strict=True)]
            swarm.step(float(fine_t[e]), targets[e], flown, command=s == 0)
            if s == 0:
                est[k] = [(r.real, r.imag) for r in swarm.r]
                cmd[k] = [(u.real, u.imag) for u in swarm.u]
        vehicles = [v + dt_s * u for v, u in zip(vehicles, swarm.u, strict=True)]
        if progress is not None and (k % PROGRESS_EVERY == 0 or k == steps):
            progress((k + 1) / (steps + 1))
    series = RunSeries(fine_t[::sub], pos, est, cmd, targets[::sub])
    return LawRun(series, sum(r.failures for r in swarm.runners))


class _Swarm:
    """Every follower's law, its inputs, and what it last published."""

    def __init__(self, scenario: Scenario, law: Law[Any], dt_s: float, dt_e: float) -> None:
        self.n = scenario.n
        # The law's periods are the engine's steps (its discretisation is what it runs at).
        setups = [dataclasses.replace(setup_for(scenario, i), period_s=dt_s, est_period_s=dt_e)
                  for i in range(self.n)]
        self.runners = [LawRunner(law, s) for s in setups]
        self.latest = [Latest(i, r.declared) for i, r in enumerate(self.runners)]
        self.u = [0j] * self.n  # the commands being flown
        self.r = [0j] * self.n  # the estimates of the last step (recorded)
        self.sent: list[FollowerState | None] = [None] * self.n
        self.seq = 0

    def step(self, t_s: float, targets: np.ndarray, vehicles: list[complex],
             command: bool) -> None:
        for i, runner in enumerate(self.runners):
            for j in runner.setup.observed:
                x, y = targets[j]
                self.latest[i].observe(runner.setup, j, complex(x, y), t_s)
        if self.seq == 0:  # before the start each publishes its p~ (agents.follower.node)
            self.sent = [self._message(i, t_s, vehicles[i], self._standing(i, t_s), 0j,
                                       NO_FIELDS) for i in range(self.n)]
        for i, runner in enumerate(self.runners):
            for j in runner.setup.peers:
                msg = self.sent[j]
                if msg is not None and j != i:
                    self.latest[i].receive(msg, t_s)
        new = list(self.sent)
        for i, runner in enumerate(self.runners):
            new[i] = self._step_one(i, runner, t_s, vehicles[i], command)
        self.sent, self.seq = new, self.seq + 1

    def _step_one(self, i: int, runner: LawRunner, t_s: float, vehicle: complex,
                  command: bool) -> FollowerState | None:
        """Follower i's step: its message (None: the law failed, the last one stands)."""
        latest = self.latest[i]
        own = Sample(vehicle, self.u[i], t_s)
        peers = stand_ins(latest.peers, runner.setup, runner.last_r, t_s)
        stepped = runner.step(t_s, command, own, latest.targets, peers)
        if stepped is None:  # the law failed: hold, as a follower does
            if command:
                self.u[i] = 0j
            self.r[i] = self._standing(i, t_s)
            return self.sent[i]
        out, fields = stepped
        if command:
            self.u[i] = out.u_m_s
        self.r[i] = out.r_m
        return self._message(i, t_s, vehicle, out.r_m, out.dr_m_s, fields)

    def _standing(self, i: int, t_s: float) -> complex:
        """Follower i's estimate while its law is not running (LawRunner)."""
        return self.runners[i].standing_estimate(self.latest[i].targets, t_s)

    def _message(self, i: int, t_s: float, vehicle: complex, r: complex, dr: complex,
                 fields: LawFields) -> FollowerState:
        u = self.u[i]
        return FollowerState(Header(f"follower-{i}", self.seq, t_s), i, (r.real, r.imag),
                             (dr.real, dr.imag), (vehicle.real, vehicle.imag),
                             (u.real, u.imag), (u.real, u.imag), t_s, fields)
