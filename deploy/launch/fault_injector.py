"""The launcher's fault injector: the scenario's `[[faults]]` (and --fault) at their times.

Signals go to the process by PID (each child is its own session).  Every fault and
every follow-up (resume, start again) is an event in launch.json, beside the deaths
and restarts of `deploy.procs.restarts`.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from agents.follower.lie import begin_signal, end_signal
from agents.scenario.faults import FaultSpec
from agents.weather.windows import wind_begin_signal, wind_end_signal
from deploy.procs.supervisor import Child, Supervisor

log = logging.getLogger("enclose.run")
STOP_GRACE_S = 10.0  # a SIGTERMed process not gone after this long is killed


@dataclass
class FaultRunner:
    sup: Supervisor
    faults: tuple[FaultSpec, ...]
    t0_s: float  # monotonic time of the experiment's start
    events: list[dict[str, Any]]  # shared with the Watchdog: one timeline in launch.json
    pending_restarts: dict[str, float] = field(default_factory=dict)  # the Watchdog's
    before_restart: Callable[[Child], None] = lambda _c: None  # as the Watchdog's
    clock: Callable[[], float] = time.monotonic
    # (experiment time, what, process): "inject" a fault, "resume" a pause, "start" again,
    # "truth": a lie ends
    _todo: list[tuple[float, str, str, FaultSpec]] = field(default_factory=list)
    paused: set[str] = field(default_factory=set)

    def __post_init__(self) -> None:
        self._todo = [(f.at_s, "inject", f.process, f) for f in self.faults]

    def check(self) -> None:
        t = self.clock() - self.t0_s
        due = [item for item in self._todo if item[0] <= t]
        for item in due:
            if self._do(*item, t):
                self._todo.remove(item)

    def _child(self, name: str) -> Child:
        return next(c for c in self.sup.children if c.name == name)

    def _event(self, t: float, name: str, event: str, **extra: Any) -> None:
        row = {"t_s": round(t, 3), "process": name, "event": event, **extra}
        self.events.append(row)
        log.warning("%s", " ".join(f"{k}={v}" for k, v in row.items()))

    def _do(self, at: float, what: str, name: str, fault: FaultSpec, t: float) -> bool:
        """Carry one item out; False to try again at the next check."""
        child = self._child(name)
        if what == "inject":
            self._inject(child, fault, t)
        elif what == "resume":
            self._signal(child, signal.SIGCONT)
            self.paused.discard(name)
            self._event(t, name, "resumed")
        elif what == "calm":
            self._signal(child, wind_end_signal())
            self._event(t, name, "gust window ended")
        elif what == "truth":
            self._signal(child, end_signal())
            self._event(t, name, "lie ended")
        elif child.poll() is None:  # "start", but the stopped process is not gone yet
            if t - at > STOP_GRACE_S:
                self._signal(child, signal.SIGKILL)
            return False
        else:
            self.pending_restarts.pop(name, None)  # the fault's own return, not the policy's
            self.before_restart(child)
            self.sup.restart(child)
            self._event(t, name, "started", pid=child.pid)
        return True

    def _inject(self, child: Child, fault: FaultSpec, t: float) -> None:
        mode = {} if fault.mode is None else {"mode": fault.mode}
        if fault.gust_std_m_s is not None:
            mode["gust_std_m_s"] = str(fault.gust_std_m_s)
        self._event(t, child.name, "fault", action=fault.action, duration_s=fault.duration_s,
                    pid=child.pid, **mode)
        if child.poll() is not None:
            log.warning("fault on %s: it is not running", child.name)
            return
        if fault.action == "kill":
            self._signal(child, signal.SIGKILL)
        elif fault.action == "lie":  # the process lies itself (agents.follower.lie)
            self._signal(child, begin_signal(fault.mode or ""))
            self._todo.append((t + (fault.duration_s or 0.0), "truth", child.name, fault))
        elif fault.action == "wind":  # the simulator changes its gusts (agents.weather)
            self._signal(child, wind_begin_signal())
            self._todo.append((t + (fault.duration_s or 0.0), "calm", child.name, fault))
        elif fault.action == "pause":
            self._signal(child, signal.SIGSTOP)
            self.paused.add(child.name)
            self._todo.append((t + (fault.duration_s or 0.0), "resume", child.name, fault))
        else:  # restart, leave: a clean stop; back after duration_s (restart: at once)
            self._signal(child, signal.SIGTERM)
            if fault.action == "restart" or fault.duration_s is not None:
                self._todo.append((t + (fault.duration_s or 0.0), "start", child.name, fault))

    def resume_all(self) -> None:
        """No process may stay stopped past the run: it could not stop cleanly."""
        for name in sorted(self.paused):
            self._signal(self._child(name), signal.SIGCONT)
        self.paused.clear()

    @staticmethod
    def _signal(child: Child, signum: int) -> None:
        if child.proc is not None and child.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                child.proc.send_signal(signum)
