"""What the launcher does when a process dies mid-run: restart policies as in systemd / Docker.

`on-failure` (the default, Docker's `on-failure:N`, systemd's `Restart=on-failure`): a
follower, target, recorder or the simulator (its vehicles reboot: the agents start them up
again, agents.shell.vehicle_loop) that exits with a non-zero code or a signal is started again
after a back-off (1 s, doubling per restart of that process, at most 8 s), at most
`max_restarts` times.  `never`: it stays dead.  A clean exit (code 0) is a leave, never
restarted.  Either way the run goes on to its end; it is aborted (DeployError) only when
it cannot: the simulator died for good (policy never, or its limit), or fewer than two
followers are alive or coming back.
Every death and restart is an event in launch.json, and the launcher exits with
EXIT_SOMETHING_DIED.
"""

from __future__ import annotations

import argparse
import logging
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from deploy.procs.supervisor import Child, Supervisor
from errors import DeployError

log = logging.getLogger("enclose.run")
RESTART_POLICIES = ("on-failure", "never")
RESTARTABLE = ("follower-", "target-", "recorder", "sim", "router-")
EXIT_SOMETHING_DIED = 3  # the run went to its end, but a process died during it


@dataclass(frozen=True)
class RestartPolicy:
    mode: str = "on-failure"
    max_restarts: int = 5  # per process
    backoff_s: float = 1.0  # before the first restart; doubles for each further one
    max_backoff_s: float = 8.0

    def __post_init__(self) -> None:
        if self.mode not in RESTART_POLICIES:
            raise DeployError(f"--restart must be one of {RESTART_POLICIES}, got {self.mode!r}")
        if self.max_restarts < 0:
            raise DeployError(f"--max-restarts must be >= 0, got {self.max_restarts}")

    def delay_s(self, restarts_so_far: int) -> float:
        return float(min(self.max_backoff_s, self.backoff_s * 2.0**restarts_so_far))

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def add_supervision_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--restart",
        choices=RESTART_POLICIES,
        default="on-failure",
        help="a follower, target, recorder or the simulator that dies: start it again "
        "(default) or not",
    )
    p.add_argument("--max-restarts", type=int, default=5, help="restarts per process at most")
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="AT_S:ACTION:TARGET[:DURATION_S]",
        help="inject a fault, e.g. 30:kill:follower-1 (as [[faults]]; repeatable; none: no fault)",
    )


def how_it_ended(code: int) -> dict[str, Any]:
    """Popen's return code as launch.json says it: a code, or the signal that killed it."""
    if code < 0:
        try:
            return {"exit_code": None, "signal": signal.Signals(-code).name}
        except ValueError:
            return {"exit_code": None, "signal": -code}
    return {"exit_code": code}


@dataclass
class Watchdog:
    """Called from the launcher's loop: records deaths, schedules and performs restarts."""

    sup: Supervisor
    policy: RestartPolicy
    t0_s: float  # monotonic time of the experiment's start: events are stamped from it
    before_restart: Callable[[Child], None] = lambda _c: None
    clock: Callable[[], float] = time.monotonic
    events: list[dict[str, Any]] = field(default_factory=list)
    pending: dict[str, float] = field(default_factory=dict)  # name -> restart due (monotonic)
    _seen: dict[str, int | None] = field(default_factory=dict)  # name -> pid already handled

    @property
    def deaths(self) -> int:
        return sum(1 for e in self.events if e["event"] == "died")

    def handled(self, child: Child) -> bool:
        """True if this process's current death is one the watchdog recorded."""
        return self._seen.get(child.name) == child.pid and child.poll() not in (None, 0)

    def check(self) -> None:
        now = self.clock()
        for child in self.sup.children:
            code = child.poll()
            if code is None or code == 0 or self._seen.get(child.name) == child.pid:
                continue
            self._seen[child.name] = child.pid
            self._died(child, code, now)
        for name, due in list(self.pending.items()):
            if now >= due:
                self._restart(name, now)
        self._can_go_on()

    def dead_for_good(self) -> list[Child]:
        """Children whose death this watchdog recorded and will not undo: one that died
        since the last check() is not among them (it may yet be restarted)."""
        return [c for c in self.sup.dead() if self.handled(c) and c.name not in self.pending]

    def rebase(self, t0_s: float, policy: RestartPolicy,
               before_restart: Callable[[Child], None]) -> None:
        """Go on from the start-up watchdog into the run: events stay, restamped from the
        experiment's start (so deaths before it have negative times), and the run's policy
        and restart hook apply from now on; restarts already made still count."""
        for e in self.events:
            e["t_s"] = round(e["t_s"] + self.t0_s - t0_s, 3)
        self.t0_s, self.policy, self.before_restart = t0_s, policy, before_restart

    def _event(self, now: float, child: Child, event: str, **extra: Any) -> None:
        row = {"t_s": round(now - self.t0_s, 3), "process": child.name, "event": event, **extra}
        self.events.append(row)
        log.warning("%s", " ".join(f"{k}={v}" for k, v in row.items()))

    def _died(self, child: Child, code: int, now: float) -> None:
        ended = how_it_ended(code)
        if not child.name.startswith(RESTARTABLE) or self.policy.mode == "never":
            self._event(now, child, "died", **ended, restart="never")
        elif child.restarts >= self.policy.max_restarts:
            self._event(now, child, "died", **ended, restart="limit reached")
        else:
            delay = self.policy.delay_s(child.restarts)
            self.pending[child.name] = now + delay
            self._event(now, child, "died", **ended, restart_in_s=delay)
            return
        if child.name == "sim":
            raise DeployError(f"the simulator died ({ended}) for good: the run cannot go on")

    def _restart(self, name: str, now: float) -> None:
        del self.pending[name]
        child = next(c for c in self.sup.children if c.name == name)
        self.before_restart(child)
        self.sup.restart(child)
        self._event(now, child, "restarted", pid=child.pid, restarts=child.restarts)

    def _can_go_on(self) -> None:
        # A follower that exited 0 has flown to the end of the run by its own clock, which
        # may be a moment ahead of ours: done, not lost.
        followers = [c for c in self.sup.children if c.name.startswith("follower-")]
        live = [c for c in followers if c.poll() in (None, 0) or c.name in self.pending]
        if len(followers) >= 2 and len(live) < 2:
            raise DeployError(
                f"only {len(live)} follower(s) left alive or restarting: the run cannot go on"
            )
