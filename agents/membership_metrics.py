"""Accuracy of the ring formed by a member set, over a time window: pure.

The same errors as `agents.core.metrics` (paper's bounds), but only over `members`,
with the successor and desired angles that `agents.membership` gives that set: after
a leave, the survivors are judged against the re-formed ring, not the planned one.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agents.core.metrics import ErrorSeries, error_series
from agents.core.timeseries import RunSeries
from agents.membership import membership
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
    eps_rho, eps_delta = scenario.run.eps_rho_m, scenario.run.eps_delta
    out: list[dict[str, object]] = []
    for k, (start, end, members) in enumerate(phases):
        row: dict[str, object] = {"from_s": start, "to_s": end, "members": list(members)}
        last = end if k == len(phases) - 1 else end - 1e-9  # the change belongs to the next
        window = (series.t_s >= start) & (series.t_s <= last)
        if len(members) >= 2 and window.sum() >= 2:
            row.update(_phase_numbers(series, scenario, members, start, last, eps_rho, eps_delta))
        out.append(row)
    return out


def _phase_numbers(series: RunSeries, scenario: Scenario, members: tuple[int, ...],
                   start: float, end: float, eps_rho: float, eps_delta: float
                   ) -> dict[str, object]:
    t, err, _ = ring_errors(series, scenario, members, start, end)
    inside = np.all((np.abs(err.e_rho_m) < eps_rho) & (np.abs(err.e_delta) < eps_delta), axis=1)
    outside = np.nonzero(~inside)[0]
    reform = None
    if inside[-1]:
        reform = 0.0 if len(outside) == 0 else float(t[outside[-1] + 1] - start)
    late = t >= 0.5 * (start + end)
    return {
        "reform_s": reform,
        "estimator_error_m": float(err.estimator_error_m[late].max()),
        "radius_error_m": float(np.abs(err.e_rho_m[late]).max()),
        "angle_error": float(np.abs(err.e_delta[late]).max()),
    }
