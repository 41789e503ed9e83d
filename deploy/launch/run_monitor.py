"""What the launcher watches during a run: the recorder's progress.json, the health of each
child and its latest status (deploy.launch.status_board): the data of its board
(deploy.launch.run_board), read from a launch's view (deploy.launch.launch_state)."""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

from deploy.launch.launch_state import LaunchState
from deploy.launch.run_board import BoardView, ProcessView
from deploy.launch.status_board import StatusBoard
from deploy.procs.supervisor import Child

log = logging.getLogger("enclose.run")


def read_progress(run_dir: Path) -> dict[str, Any]:
    """The recorder's progress.json ({} until it exists; it is replaced atomically)."""
    try:
        doc = json.loads((run_dir / "progress.json").read_text())
    except (OSError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}


def health_of(child: Child, paused: Collection[str], pending: Collection[str]) -> str:
    code = child.poll()
    if code is None:
        return "paused" if child.name in paused else "up"
    if child.name in pending:
        return "restarting"
    return f"exited {code}" if code >= 0 else f"killed ({-code})"


def process_views(children: Sequence[Child], board: StatusBoard, paused: Collection[str],
                  pending: Collection[str]) -> tuple[ProcessView, ...]:
    # Statuses are keyed role-index: "sim-0" and "recorder-0" for the children "sim", "recorder".
    return tuple(ProcessView(c.name, health_of(c, paused, pending),
                             board.state_of(c.name) or board.state_of(f"{c.name}-0"), c.restarts)
                 for c in children)


def event_text(e: dict[str, Any]) -> str:
    rest = " ".join(f"{k}={v}" for k, v in e.items() if k not in ("t_s", "process", "event"))
    return f"{e.get('t_s', 0.0):.1f} s {e.get('process', '?')} {e.get('event', '?')} {rest}"




def launch_view(launch: LaunchState) -> BoardView:
    """What the launcher's live board shows now."""
    progress = read_progress(launch.out)
    inj, dog = launch.injector, launch.watchdog
    events = [] if dog is None else dog.events[-3:]
    run = launch.scenario.run
    # The live view's address (another part of the launcher may set it): shown when known.
    live_url = getattr(launch, "live_url", None) or progress.get("live_url")
    return BoardView(
        f"enclose run {launch.scenario.name}", time.monotonic() - launch.started_s,
        time.monotonic() - launch.t0_s, launch.duration_s,
        {"rho": run.eps_rho_m, "delta": run.eps_delta}, progress,
        process_views(launch.sup.children, launch.board, () if inj is None else inj.paused,
                      () if dog is None else dog.pending),
        tuple(event_text(e) for e in events),
        live_url if isinstance(live_url, str) else None,
    )
