"""What the launcher watches during a run: every process's latest status, the recorder's
progress.json, and the health of each child: the data of its board (deploy.launch.run_board)."""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deploy.launch.run_board import BoardView, ProcessView
from deploy.procs.supervisor import Child
from transport.bus import Subscription
from transport.decoder import Decoder
from transport.message_checks import DEFAULT_LIMITS
from transport.messages import ProcessStatus

if TYPE_CHECKING:
    from deploy.launch.launcher import Launch

log = logging.getLogger("enclose.run")


class StatusBoard:
    """Each process's latest ProcessStatus (its final counters go to launch.json).

    A status counts only from the process it names, on its own key (transport.message_checks):
    the table holds at most one entry per sender of the scenario (`senders`)."""

    def __init__(self, senders: Collection[str]) -> None:
        self.subscription: Subscription | None = None
        self.latest: dict[str, ProcessStatus] = {}
        self.decoder = Decoder(expect=(ProcessStatus,), limits=DEFAULT_LIMITS, senders=senders)

    def collect(self) -> None:
        if self.subscription is None:
            return
        for inbound in self.decoder.drain(self.subscription):
            msg = inbound.message
            if isinstance(msg, ProcessStatus):
                self.latest[f"{msg.role}-{msg.index}"] = msg

    def state_of(self, name: str) -> str:
        status = self.latest.get(name)
        return "" if status is None else status.state

    def as_dict(self) -> dict[str, Any]:
        return {name: {"state": s.state, **s.counters} for name, s in self.latest.items()}


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




def launch_view(launch: Launch) -> BoardView:
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
