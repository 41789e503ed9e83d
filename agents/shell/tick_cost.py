"""What a tick costs, phase by phase, and what the process's other threads cost meanwhile.

The loop marks the end of each phase (`TickCost.mark`); the loop thread's CPU since the
previous mark goes to that phase.  The process's threads are read from
/proc/self/task/<tid>/schedstat (nanoseconds on a CPU, kernel time included) at the start
of the measured stretch and whenever counters are asked for, and grouped: the loop's own
thread, Zenoh's runtime threads (named rx-, tx-, net-, acc-, app-), the rest (the stall
guard).  Off unless ENCLOSE_TICK_COST is set (bench/bench_tick_cost.py): a mark reads the
thread's CPU clock, a system call of ~0.3 us, and a tick has nine.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

# In the order a tick runs them.  `wait` is the sleep to the tick and its wake-up; `loop`
# what the loop does around the node (stall guard, offboard keeper, status).
PHASES = ("wait", "members", "receive", "mav_in", "law", "journal", "mav_out", "publish",
          "loop")
ZENOH_THREADS = ("rx-", "tx-", "net-", "acc-", "app-")
TASKS = Path("/proc/self/task")
ENV = "ENCLOSE_TICK_COST"


def thread_cpu_ns(tasks: Path = TASKS, main: int | None = None) -> dict[str, int]:
    """CPU so far of this process's threads, ns, by group: "main" (thread `main`, by
    default the one that asks), "zenoh", "other".  Threads that ended are gone from the sum."""
    main = threading.get_native_id() if main is None else main
    out = {"main": 0, "zenoh": 0, "other": 0}
    for task in tasks.iterdir():
        try:
            run_ns = int((task / "schedstat").read_text().split()[0])
            comm = (task / "comm").read_text().strip()
        except (OSError, ValueError, IndexError):  # a thread that just ended
            continue
        if task.name == str(main):
            out["main"] += run_ns
        elif comm.startswith(ZENOH_THREADS):
            out["zenoh"] += run_ns
        else:
            out["other"] += run_ns
    return out


class TickCost:
    """Phase CPU of the loop thread (`mark`), and thread-group CPU, from `begin` on."""

    enabled = True

    def __init__(self, tasks: Path = TASKS, clock: Callable[[], int] = time.thread_time_ns,
                 main: int | None = None) -> None:
        self.tasks, self.clock = tasks, clock
        self.main = threading.get_native_id() if main is None else main  # the loop's thread
        self.ns = dict.fromkeys(PHASES, 0)
        self.ticks = 0
        self._last_ns: int | None = None
        self._threads0: dict[str, int] | None = None

    def begin(self) -> None:
        """Start (again) from here: the steady stretch, not the start-up."""
        self.ns = dict.fromkeys(PHASES, 0)
        self.ticks = 0
        self._last_ns = self.clock()
        self._threads0 = thread_cpu_ns(self.tasks, self.main)

    def mark(self, phase: str) -> None:
        if self._last_ns is None:
            return
        now = self.clock()
        self.ns[phase] += now - self._last_ns
        self._last_ns = now
        if phase == "wait":
            self.ticks += 1

    def counters(self) -> dict[str, int]:
        """cost_ticks, cost_us_<phase> and cost_us_thread_<group>, summed since `begin`."""
        if self._threads0 is None:
            return {}
        now = thread_cpu_ns(self.tasks, self.main)
        out = {"cost_ticks": self.ticks}
        out.update({f"cost_us_{p}": ns // 1000 for p, ns in self.ns.items()})
        out.update({f"cost_us_thread_{g}": (now[g] - self._threads0.get(g, 0)) // 1000
                    for g in now})
        return out


class NoCost:
    """The loop's marks when nothing is measured."""

    enabled = False

    def begin(self) -> None:
        pass

    def mark(self, phase: str) -> None:
        pass

    def counters(self) -> dict[str, int]:
        return {}


def tick_cost() -> TickCost | NoCost:
    """A TickCost where ENCLOSE_TICK_COST is set, else the no-op."""
    return TickCost() if os.environ.get(ENV) else NoCost()
