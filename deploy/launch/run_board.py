"""The launcher's live status board: elapsed time, every process, errors against the
paper's bounds, link health.  On a terminal it is one board redrawn in place (rich);
piped, it is a log line every few seconds, with no escape codes.

`board_view` gathers what the board shows (pure data); `render_board` and `board_line`
turn it into the board or the line; `LiveBoard` decides which and when.
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

log = logging.getLogger("enclose.run")
# progress.json key -> (label, unit, which bound)
ERRORS = (
    ("max_estimator_error_m", "estimator |r-LAP|", "m", "rho"),
    ("max_abs_e_rho_m", "radius |e_rho|", "m", "rho"),
    ("max_abs_e_delta", "angle |e_delta|", "", "delta"),
)
MAX_ROWS = 10  # more processes than this: followers as one row, plus any not healthy
REDRAW_S = 1.0  # progress.json changes once a second: redrawing faster shows nothing new
BEHIND_SHOWN_S = 2.0  # a recorder further behind the bus than this: its live figures lag
RECORDING_STATES = ("linked", "running")  # after these no input is due: "behind" means nothing


@dataclass(frozen=True)
class ProcessView:
    name: str
    health: str  # "up", "paused", "restarting", "exited 0", "died (-9)", ...
    state: str  # its last ProcessStatus state ("linked", "running", "done"), or ""
    restarts: int = 0

    @property
    def healthy(self) -> bool:
        return self.health == "up" and self.restarts == 0


@dataclass(frozen=True)
class BoardView:
    title: str
    elapsed_s: float  # wall time since the launcher started
    t_s: float  # experiment time
    duration_s: float
    bounds: dict[str, float]  # "rho": m, "delta"
    progress: dict[str, Any]  # the recorder's progress.json
    processes: tuple[ProcessView, ...]
    events: tuple[str, ...] = ()  # the newest few, as text
    live_url: str | None = None
    extra: dict[str, str] = field(default_factory=dict)


def _num(v: Any) -> float | None:
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else None


def error_cells(view: BoardView) -> Iterator[tuple[str, str, str, bool | None]]:
    """(label, value, bound, inside) per error of the last second."""
    for key, label, unit, which in ERRORS:
        value, bound = _num(view.progress.get(key)), view.bounds[which]
        u = f" {unit}" if unit else ""
        shown = "-" if value is None else f"{value:.4g}{u}"
        yield label, shown, f"< {bound:g}{u}", None if value is None else value < bound

SILENT_NAMED = 4


def link_text(progress: dict[str, Any]) -> str:
    links = progress.get("links")
    if not isinstance(links, dict) or not links.get("count"):
        return "no link counters yet"
    parts = [f"{links['count']} links"]
    if _num(links.get("min_delivered")) is not None:
        worst = links["min_delivered_link"]
        parts.append(f"worst delivered {links['min_delivered']:.2f} ({worst})")
    if _num(links.get("max_age_ms")) is not None:
        parts.append(f"oldest {links['max_age_ms']:.1f} ms ({links['max_age_link']})")
    silent = links.get("silent") or []
    if silent:  # a big ring can have dozens: name a few, count the rest
        more = f" (+{len(silent) - SILENT_NAMED} more)" if len(silent) > SILENT_NAMED else ""
        parts.append(f"silent {len(silent)}: {', '.join(silent[:SILENT_NAMED])}{more}")
    return ", ".join(parts)


def lag_text(progress: dict[str, Any]) -> str | None:
    """The recorder's backlog when it is large: the errors and links shown are that old."""
    behind = _num(progress.get("recorder_behind_s"))
    if behind is None or behind <= BEHIND_SHOWN_S or progress.get("state") not in RECORDING_STATES:
        return None
    return f"recorder {behind:.1f} s behind (live figures lag)"


def process_rows(processes: Sequence[ProcessView]) -> list[ProcessView]:
    """Every process, or for a big swarm the followers as one row and every unhealthy one."""
    if len(processes) <= MAX_ROWS:
        return list(processes)
    followers = [p for p in processes if p.name.startswith("follower-")]
    up = sum(p.health == "up" for p in followers)
    states = sorted({p.state for p in followers if p.state})
    summary = ProcessView(f"followers ({len(followers)})", f"{up} up", "/".join(states))
    return [p for p in processes if p not in followers or not p.healthy] + [summary]


def _mark(inside: bool | None) -> Text:
    if inside is None:
        return Text("")
    return Text("ok", style="green") if inside else Text("over", style="bold red")


def render_board(view: BoardView) -> Group:
    head = Text.assemble(
        (f"{view.title}  ", "bold"),
        f"t = {max(0.0, view.t_s):.1f} / {view.duration_s:g} s   elapsed {view.elapsed_s:.0f} s",
    )
    errors = Table(box=None, pad_edge=False, show_header=True, header_style="bold")
    for col in ("error (last 1 s)", "now", "paper's bound", ""):
        errors.add_column(col)
    for label, value, bound, inside in error_cells(view):
        errors.add_row(label, value, bound, _mark(inside))
    procs = Table(box=None, pad_edge=False, header_style="bold")
    for col in ("process", "health", "state", "restarts"):
        procs.add_column(col)
    for p in process_rows(view.processes):
        style = "" if p.health.startswith(("up", "exited 0")) else "yellow"
        procs.add_row(p.name, Text(p.health, style=style), p.state, str(p.restarts or ""))
    lines: list[Any] = [head, errors, procs, Text(f"links: {link_text(view.progress)}")]
    lag = lag_text(view.progress)
    if lag:
        lines.append(Text(lag, style="yellow"))
    lines += [Text(f"{k}: {v}") for k, v in view.extra.items()]
    if view.live_url:
        lines.append(Text(f"live view: {view.live_url}"))
    lines += [Text(f"event: {e}", style="yellow") for e in view.events]
    return Group(*lines)


def board_line(view: BoardView) -> str:
    """The board as one plain line (piped output)."""
    errs = "  ".join(
        f"{label} {value}" + ("" if inside is None else " ok" if inside else " OVER")
        for label, value, _, inside in error_cells(view)
    )
    up = sum(p.health == "up" for p in view.processes)
    lag = lag_text(view.progress)
    return (f"t = {max(0.0, view.t_s):6.1f} / {view.duration_s:g} s  {errs}  "
            f"processes {up}/{len(view.processes)} up  links: {link_text(view.progress)}"
            + (f"  {lag}" if lag else ""))


class LiveBoard:
    """Shows `make_view()` during the flight: redrawn in place on a terminal (stderr),
    logged every `line_period_s` otherwise."""

    def __init__(self, make_view: Callable[[], BoardView], line_period_s: float = 2.0,
                 console: Console | None = None) -> None:
        self.make_view, self.line_period_s = make_view, line_period_s
        self.console = console or Console(stderr=True)
        self.live: Live | None = None
        self._next_s = 0.0
        self._handlers: list[tuple[logging.StreamHandler[Any], Any]] = []

    @property
    def tty(self) -> bool:
        return self.console.is_terminal

    def __enter__(self) -> LiveBoard:
        if self.tty:
            self.live = Live(render_board(self.make_view()), console=self.console,
                             auto_refresh=False, transient=False)
            self.live.start(refresh=True)
            self._route_logging()
        return self

    def _route_logging(self) -> None:
        """Log lines go above the board (rich's stderr proxy), not through it."""
        for h in logging.getLogger().handlers:
            if isinstance(h, logging.StreamHandler) and h.stream is self.console.file:
                self._handlers.append((h, h.stream))
                h.setStream(sys.stderr)

    def __exit__(self, *exc: object) -> None:
        if self.live is not None:
            for h, stream in self._handlers:
                h.setStream(stream)
            self._handlers.clear()
            self.live.update(render_board(self.make_view()), refresh=True)
            self.live.stop()
            self.live = None

    def tick(self) -> None:
        now = time.monotonic()
        if now < self._next_s:
            return
        if self.live is not None:
            self._next_s = now + REDRAW_S
            self.live.update(render_board(self.make_view()), refresh=True)
        else:
            self._next_s = now + self.line_period_s
            log.info("%s", board_line(self.make_view()))
