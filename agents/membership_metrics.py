"""Accuracy of the ring formed by a member set, over a time window: pure.

The same errors as `agents.core.metrics` (paper's bounds), but only over `members`,
with the successor and desired angles that `agents.membership` gives that set: after
a leave, the survivors are judged against the re-formed ring, not the planned one.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from agents.core.metrics import error_series
from agents.core.timeseries import RunSeries
from agents.membership import membership
from agents.scenario import Scenario


@dataclass(frozen=True)
class PhaseErrors:
    members: tuple[int, ...]
    from_s: float
    to_s: float
    estimator_error_m: float  # max |r_i - LAP|
    radius_error_m: float  # max |e_rho|
    angle_error: float  # max |e_delta| against the re-formed ring's angles
    spacing_spread_rad: float  # max - min of each member's included angle over the window


def phase_errors(
    series: RunSeries, scenario: Scenario, members: Iterable[int], from_s: float, to_s: float
) -> PhaseErrors:
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
    err = error_series(sub, successor, angles, scenario.pattern.rho_d_m)
    included = (err.e_delta + 1.0) * angles
    return PhaseErrors(
        members=tuple(idx),
        from_s=from_s,
        to_s=to_s,
        estimator_error_m=float(err.estimator_error_m.max()),
        radius_error_m=float(np.abs(err.e_rho_m).max()),
        angle_error=float(np.abs(err.e_delta).max()),
        spacing_spread_rad=float((included.max(axis=0) - included.min(axis=0)).max()),
    )
