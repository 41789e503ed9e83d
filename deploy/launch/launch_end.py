"""How a launched run ends: the processes stopped in order, launch.json's content, the exit code.

Apart from `deploy.launch.launcher`, which wires the processes and flies the run: none of this runs
before the flight is over.  These are functions of a `Launch`, as
`deploy.launch.run_monitor.launch_view` is, so that the class keeps to its wiring and its flight;
`Launch.report` stays a method because a host's launcher (deploy.hosts.host_launch) extends it.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

from agents.shell.phases import stamps
from deploy.launch.launch_state import LaunchState
from deploy.procs.restarts import EXIT_SOMETHING_DIED
from deploy.report.cpu_load import overrun_summary
from deploy.report.verdict import announce
from enclose_release import VERSION

log = logging.getLogger("enclose.run")


def stop_in_order(launch: LaunchState) -> None:
    """Movers end on the stop word; the recorder then writes its outputs; the sim last."""
    sup = launch.sup
    movers = [c for c in sup.children if c.name.startswith(("follower", "target"))]
    if not sup.wait(movers, 10.0):
        sup.terminate(movers)
    deadline = time.monotonic() + 1.0  # their final status may still be on the wire
    while time.monotonic() < deadline and not all(
        launch.board.state_of(c.name) == "done" for c in movers
    ):
        launch.board.collect()
        time.sleep(0.02)
    recorder = [c for c in sup.children if c.name == "recorder"]
    if not sup.wait(recorder, 120.0):
        log.error("recorder did not finish writing in 120 s; stopping it")
        sup.terminate(recorder)
    sup.terminate([c for c in sup.children if c.name == "sim"])


def launch_report(launch: LaunchState) -> dict[str, Any]:
    """The content of launch.json (a host's launcher adds its hosts: deploy.hosts.host_launch)."""
    return {
        "enclose_version": VERSION,
        "swarm": launch.keys.swarm,
        "zenoh_endpoint": launch.endpoint,
        "vehicle_base_port": launch.vehicle_base,
        "adapter_base_port": launch.adapter_base,
        "duration_s": launch.duration_s,
        "live_url": launch.live_url,
        **launch.timings,
        "start_phases": stamps(),  # CLOCK_MONOTONIC s (agents.shell.phases; bench/bench_start.py)
        "processes": {
            c.name: {"pid": c.pid, "exit_code": c.poll(), "restarts": c.restarts,
                     "spawned_s": c.spawned_s}
            for c in launch.sup.children
        },
        "restart_policy": launch.policy.as_dict(),
        "faults": [f.__dict__ for f in launch.faults],
        "events": [] if launch.watchdog is None else launch.watchdog.events,
        "status": launch.board.as_dict(),
        "status_at_stop": launch.status_at_stop,
        # What the launcher itself refused (statuses not from the process they name).
        "launcher": launch.board.decoder.counters(),
        "load": load_report(launch),
    }


def load_report(launch: LaunchState) -> dict[str, Any]:
    """CPU per process and machine busy over the steady half (deploy.report.cpu_load), and the
    followers' late ticks: the load an accuracy figure was measured under."""
    steady_from = launch.t0_s + 0.5 * launch.duration_s
    if not math.isfinite(launch.t0_s):  # it never flew: nothing was sampled
        return {"ticks": overrun_summary(launch.board.as_dict())}
    cpu = launch.cpu.summary(steady_from if steady_from < time.monotonic() else launch.t0_s)
    return {**cpu, "ticks": overrun_summary(launch.board.as_dict())}


def exit_code(launch: LaunchState, interrupted: bool) -> int:
    """130 interrupted; 1 a process failed at the end; EXIT_SOMETHING_DIED (3) a process
    died during the run (launch.json "events") but the run went to its end; else 0."""
    dog = launch.watchdog
    failed = [c for c in launch.sup.dead() if dog is None or not dog.handled(c)]
    for c in failed:
        log.error("%s exited with code %s (log: %s)", c.name, c.exit_code, c.log_path)
    title = f"enclose run {launch.scenario.name}"
    announce(launch.out, title, launch.opts.json,
             "interrupted" if interrupted else "")
    if interrupted:
        return 130
    if failed:
        return 1
    return EXIT_SOMETHING_DIED if dog is not None and dog.deaths else 0
