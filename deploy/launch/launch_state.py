"""What the end of a run and the live board read of a launch: a narrow, read-only view.

`deploy.launch.launcher.Launch` (and a host's launcher, deploy.hosts.host_launch) has these;
`deploy.launch.launch_end` and `deploy.launch.run_monitor` take this view, not the class, so
that the launcher imports them and nothing imports the launcher back.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

from agents.scenario.faults import FaultSpec
from agents.scenario.model import Scenario
from deploy.launch.fault_injector import FaultRunner
from deploy.launch.launch_options import LaunchOptions
from deploy.launch.status_board import StatusBoard
from deploy.procs.restarts import RestartPolicy, Watchdog
from deploy.procs.supervisor import Supervisor
from deploy.report.cpu_load import CpuSampler
from transport.key_exprs import SwarmKeys


class LaunchState(Protocol):
    """A launch as its end and its board see it: what it was asked, its processes, their
    statuses, and the times of its start (monotonic s)."""

    @property
    def scenario(self) -> Scenario: ...
    @property
    def opts(self) -> LaunchOptions: ...
    @property
    def out(self) -> Path: ...
    @property
    def keys(self) -> SwarmKeys: ...
    @property
    def duration_s(self) -> float: ...
    @property
    def endpoint(self) -> str: ...
    @property
    def vehicle_base(self) -> int: ...
    @property
    def adapter_base(self) -> int: ...
    @property
    def live_url(self) -> str | None: ...
    @property
    def timings(self) -> dict[str, float]: ...
    @property
    def sup(self) -> Supervisor: ...
    @property
    def board(self) -> StatusBoard: ...
    @property
    def status_at_stop(self) -> dict[str, Any] | None: ...
    @property
    def policy(self) -> RestartPolicy: ...
    @property
    def watchdog(self) -> Watchdog | None: ...
    @property
    def faults(self) -> tuple[FaultSpec, ...]: ...
    @property
    def injector(self) -> FaultRunner | None: ...
    @property
    def cpu(self) -> CpuSampler: ...
    @property
    def started_s(self) -> float: ...
    @property
    def t0_s(self) -> float: ...
