"""What the launcher watches during a run: every process's latest status, and live progress."""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path
from typing import Any

from transport.bus import Subscription
from transport.decoder import Decoder
from transport.messages import ProcessStatus

log = logging.getLogger("enclose.run")
PROGRESS_FIELDS = (
    ("max_estimator_error_m", "|r-LAP| m"),
    ("max_abs_e_rho_m", "|e_rho| m"),
    ("max_abs_e_delta", "|e_delta|"),
)


class StatusBoard:
    """Each process's latest ProcessStatus (its final counters go to launch.json)."""

    def __init__(self) -> None:
        self.subscription: Subscription | None = None
        self.latest: dict[str, ProcessStatus] = {}
        self.decoder = Decoder(expect=(ProcessStatus,))

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


def show_progress(run_dir: Path, t_s: float, duration_s: float) -> None:
    """One line from the recorder's progress.json: on a terminal in place, else logged."""
    try:
        p = json.loads((run_dir / "progress.json").read_text())
    except (OSError, ValueError):
        p = {}
    errs = "  ".join(
        f"{label} {p[key]:.3g}" for key, label in PROGRESS_FIELDS if isinstance(p.get(key), float)
    )
    line = f"t = {max(0.0, t_s):6.1f} / {duration_s:.0f} s  {errs}"
    if sys.stderr.isatty():
        sys.stderr.write("\r" + line.ljust(100))
        sys.stderr.flush()
    else:
        log.info("%s", line)
