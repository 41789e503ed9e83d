"""Accuracy of the ring formed by a member set, over a time window: pure.

The same errors as `agents.analysis.metrics` (paper's bounds), but only over `members`,
with the successor and desired angles that `agents.membership.ring` gives that set: after
a leave, the survivors are judged against the re-formed ring, not the planned one.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agents.analysis.metrics import ErrorSeries, error_series
from agents.analysis.timeseries import RunSeries
from agents.membership.ring import membership
from agents.scenario.model import Scenario

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PhaseErrors:
    members: tuple[int, ...]
    from_s: float
    to_s: float
    estimator_error_m: float  # max |r_i - LAP|
    radius_error_m: float  # max |e_rho|
    angle_error: float  # max |e_delta| against the re-formed ring's angles
    spacing_spread_rad: float  # max - min of each member's included angle over the window


def ring_errors(
    series: RunSeries, scenario: Scenario, members: Iterable[int], from_s: float, to_s: float
) -> tuple[FloatArray, ErrorSeries, FloatArray]:
    """Times, errors and desired angles of the ring `members` form, between from_s and to_s."""
    form = membership(scenario, members)
    idx = list(form.members)
    local = {i: k for k, i in enumerate(idx)}
    window = (series.t_s >= from_s) & (series.t_s <= to_s)
    if not np.any(window):
        raise ValueError(f"no samples between {from_s} and {to_s} s")
    sub = RunSeries(
        series.t_s[window],
        series.follower_pos_m[window][:, idx],
        series.estimate_m[window][:, idx],
        series.command_m_s[window][:, idx],
        series.target_pos_m[window],
    )
    successor = tuple(local[form.successor[i]] for i in idx)
    angles = np.array([form.angles_rad[i] for i in idx])
    return sub.t_s, error_series(sub, successor, angles, scenario.pattern.rho_d_m), angles


def phase_errors(
    series: RunSeries, scenario: Scenario, members: Iterable[int], from_s: float, to_s: float
) -> PhaseErrors:
    members = tuple(sorted(members))
    _, err, angles = ring_errors(series, scenario, members, from_s, to_s)
    included = (err.e_delta + 1.0) * angles
    return PhaseErrors(
        members=members,
        from_s=from_s,
        to_s=to_s,
        estimator_error_m=float(err.estimator_error_m.max()),
        radius_error_m=float(np.abs(err.e_rho_m).max()),
        angle_error=float(np.abs(err.e_delta).max()),
        spacing_spread_rad=float((included.max(axis=0) - included.min(axis=0)).max()),
    )


def membership_phases(
    changes: list[tuple[float, frozenset[int]]], t_end_s: float
) -> list[tuple[float, float, tuple[int, ...]]]:
    """(from, to, members) per phase, from (experiment time, member set) changes.

    Changes before t = 0 (while the swarm linked) only set the first phase's members.
    """
    phases: list[tuple[float, float, tuple[int, ...]]] = []
    current: tuple[int, ...] | None = None
    start = 0.0
    for t, members in sorted(changes, key=lambda c: c[0]):
        if t >= t_end_s:
            break  # processes ending after the run: not a phase of it
        if t > 0.0 and current is not None:
            phases.append((start, t, current))
            start = t
        current = tuple(sorted(members))
    if current is not None:
        phases.append((start, t_end_s, current))
    return phases


def phase_report(
    series: RunSeries,
    scenario: Scenario,
    phases: list[tuple[float, float, tuple[int, ...]]],
) -> list[dict[str, object]]:
    """Per phase: its members, the time the re-formed ring took to enter the paper's bounds
    (|e_rho| < eps_rho and |e_delta| < eps_delta for every member, to the end of the phase;
    None if it never did) and the largest errors over the phase's second half."""
    report = PhaseReport(scenario, phases)
    report.add(series)
    return report.result()


class _Phase:
    """One phase's numbers, gathered chunk by chunk."""

    def __init__(self, scenario: Scenario, start: float, end: float,
                 members: tuple[int, ...], last: bool) -> None:
        self.start, self.end, self.members = start, end, members
        self.to_s = end if last else end - 1e-9  # the change belongs to the next
        self.rows = 0
        self.ring: tuple[list[int], tuple[int, ...], FloatArray] | None = None
        if len(members) >= 2:
            form = membership(scenario, members)
            idx = list(form.members)
            local = {i: k for k, i in enumerate(idx)}
            self.ring = (idx, tuple(local[form.successor[i]] for i in idx),
                         np.array([form.angles_rad[i] for i in idx]))
        self.reform: float | None = None  # the first sample after the last one outside
        self.reform_next = False
        self.inside_last = False
        self.late: list[float] = [-np.inf] * 3  # estimator, radius, angle (NaN shows)
        self.late_rows = 0

    def add(self, series: RunSeries, rho_d_m: float, eps: tuple[float, float]) -> None:
        window = (series.t_s >= self.start) & (series.t_s <= self.to_s)
        if not np.any(window):
            return
        self.rows += int(window.sum())
        if self.ring is None:
            return
        idx, successor, angles = self.ring
        sub = RunSeries(series.t_s[window], series.follower_pos_m[window][:, idx],
                        series.estimate_m[window][:, idx], series.command_m_s[window][:, idx],
                        series.target_pos_m[window])
        err = error_series(sub, successor, angles, rho_d_m)
        t = sub.t_s
        inside = np.all((np.abs(err.e_rho_m) < eps[0]) & (np.abs(err.e_delta) < eps[1]), axis=1)
        if self.reform_next:
            self.reform, self.reform_next = float(t[0] - self.start), False
        outside = np.nonzero(~inside)[0]
        if len(outside):
            if outside[-1] + 1 < len(t):
                self.reform = float(t[outside[-1] + 1] - self.start)
            else:
                self.reform_next = True
        self.inside_last = bool(inside[-1])
        late = t >= 0.5 * (self.start + self.to_s)
        if np.any(late):
            self.late_rows += int(late.sum())
            for k, values in enumerate((err.estimator_error_m[late], np.abs(err.e_rho_m[late]),
                                        np.abs(err.e_delta[late]))):
                v = float(values.max())
                self.late[k] = np.nan if np.isnan(v) or np.isnan(self.late[k]) \
                    else max(self.late[k], v)

    def result(self) -> dict[str, object]:
        row: dict[str, object] = {"from_s": self.start, "to_s": self.end,
                                  "members": list(self.members)}
        if self.ring is not None and self.rows >= 2:
            late = [v if self.late_rows else None for v in self.late]
            row.update({
                "reform_s": (0.0 if self.reform is None else self.reform)
                if self.inside_last else None,
                "estimator_error_m": late[0], "radius_error_m": late[1], "angle_error": late[2],
            })
        return row


class PhaseReport:
    """`phase_report` of a series fed in consecutive chunks (time order)."""

    def __init__(self, scenario: Scenario,
                 phases: list[tuple[float, float, tuple[int, ...]]]) -> None:
        self.rho_d_m = scenario.pattern.rho_d_m
        self.eps = (scenario.run.eps_rho_m, scenario.run.eps_delta)
        self.phases = [_Phase(scenario, start, end, members, k == len(phases) - 1)
                       for k, (start, end, members) in enumerate(phases)]

    def add(self, series: RunSeries) -> None:
        for phase in self.phases:
            phase.add(series, self.rho_d_m, self.eps)

    def result(self) -> list[dict[str, object]]:
        return [phase.result() for phase in self.phases]
