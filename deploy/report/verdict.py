"""The end of a run, in a few lines: inside the paper's bounds or not (per metric, with the
bound), settle time, what died or restarted, link health, where the files are.

`read_verdict(run_dir)` reads metrics.json, run.json (the bounds the run was judged
against) and, for networked runs, launch.json; `print_verdict` prints it with rich (plain
text when not on a terminal); `verdict_json` is what `--json` prints for scripts.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table
from rich.text import Text

from deploy.json_files import read_json
from deploy.report.cpu_load import load_line, memory_line, overrun_line
from deploy.report.liars import liar_lines
from deploy.report.refusals import launch_refusals, refusal_text
from deploy.report.weather_report import weather_lines

# metrics.json key -> (label, unit, run.json key of its bound)
BOUNDED = (
    ("estimator_error_m", "estimator error |r-LAP|", "m", "eps_rho_m"),
    ("radius_error_m", "radius error |e_rho|", "m", "eps_rho_m"),
    ("angle_error", "angle error |e_delta|", "", "eps_delta"),
)
PAPER_BOUNDS = {"eps_rho_m": 0.0999, "eps_delta": 0.0199}  # agents.scenario.model defaults
FILES = ("metrics.json", "series.csv", "series.parquet", "performance.png", "trajectory.png",
         "links.png", "recording.mcap", "launch.json", "logs")


@dataclass(frozen=True)
class Check:
    key: str
    label: str
    unit: str
    value: float | None
    bound: float
    floor: bool = False  # the value must stay at or above the bound (a distance)

    @property
    def inside(self) -> bool:
        if self.value is None:
            return False
        return self.value >= self.bound if self.floor else self.value < self.bound

    def bound_text(self) -> str:
        u = f" {self.unit}" if self.unit else ""
        return f"{'>=' if self.floor else '<'} {self.bound:g}{u}"

    def text(self) -> str:
        u = f" {self.unit}" if self.unit else ""
        return "none" if self.value is None else f"{self.value:.4g}{u}"


@dataclass(frozen=True)
class Verdict:
    title: str
    run_dir: Path
    checks: tuple[Check, ...]
    error: str | None  # no metrics: why
    metrics: dict[str, Any]
    processes: tuple[str, ...]  # what died, restarted, was faulted or failed
    links: str | None
    live_url: str | None
    files: tuple[str, ...]
    note: str = ""  # e.g. "interrupted"
    networked: bool = False  # a launch.json exists: processes to report on
    load: str | None = None  # CPU per process and machine busy (deploy.report.cpu_load)
    ticks: str | None = None  # the followers' late control ticks
    memory: str | None = None  # peak resident memory per process (deploy.report.cpu_load)
    silent: tuple[int, ...] = ()  # 0-based followers that sent no state: not judged whole
    recording: str | None = None  # what the recorder lost, when it lost enough to matter
    # bus input the processes refused (deploy.report.refusals)
    refused: dict[str, Any] | None = None
    law: str | None = None  # the followers' law and how often it failed in flight
    network: tuple[str, ...] = ()  # each network fault: its window, recovery, closest approach
    liars: tuple[str, ...] = ()  # followers refused as implausible (deploy.report.liars)
    # wind, GPS noise, sensing and its misses (deploy.report.weather_report)
    weather: tuple[str, ...] = ()

    @property
    def inside(self) -> bool:
        return self.error is None and not self.silent and all(c.inside for c in self.checks)


def _read(path: Path) -> dict[str, Any]:
    return read_json(path) or {}


def _num(v: Any) -> float | None:
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else None


def _dict(v: Any) -> dict[str, Any]:
    return v if isinstance(v, dict) else {}


def process_lines(launch: dict[str, Any]) -> tuple[str, ...]:
    """One line per process that did not simply run and exit 0; empty: all fine."""
    counts: dict[str, dict[str, int]] = {}
    for e in launch.get("events") or []:
        if isinstance(e, dict) and isinstance(e.get("event"), str):
            per = counts.setdefault(str(e.get("process", "?")), {})
            per[e["event"]] = per.get(e["event"], 0) + 1
    procs = launch.get("processes") or {}
    for name, p in procs.items():
        code = p.get("exit_code") if isinstance(p, dict) else None
        if code not in (0, None):
            counts.setdefault(name, {})[f"exit code {code}"] = 0
    return tuple(
        f"{name}: " + ", ".join(k if n == 0 else f"{k} {n}x" for k, n in sorted(per.items()))
        for name, per in sorted(counts.items())
    )


def link_summary(metrics: dict[str, Any]) -> str | None:
    links = metrics.get("links")
    if not isinstance(links, dict) or not links:
        return None
    ratios = [(_num(v.get("delivered_ratio")), k) for k, v in links.items() if isinstance(v, dict)]
    ages = [(_num(v.get("age_p99_ms")), k) for k, v in links.items() if isinstance(v, dict)]
    worst = min(((r, k) for r, k in ratios if r is not None), default=None)
    oldest = max(((a, k) for a, k in ages if a is not None), default=None)
    parts = [f"{len(links)} links"]
    if worst is not None:
        parts.append(f"delivered >= {worst[0]:.3f} (worst {worst[1]})")
    if oldest is not None:
        parts.append(f"age p99 <= {oldest[0]:.1f} ms ({oldest[1]})")
    return ", ".join(parts)


LOST_WORTH_SAYING = 0.01  # of the messages the recorder should have had


def recording_line(metrics: dict[str, Any]) -> str | None:
    """What the recorder lost (sequence gaps) or refused, when over 1 % of what was sent:
    a starved recorder judges the run on stale states (ring64 on a saturated machine)."""
    decoder = _dict(_dict(metrics.get("recorder")).get("decoder"))
    accepted, gaps = _num(decoder.get("accepted")) or 0.0, _num(decoder.get("seq_gap")) or 0.0
    refused = sum(_num(v) or 0.0 for k, v in decoder.items() if k.startswith("drop_"))
    sent = accepted + gaps
    if sent <= 0 or gaps < LOST_WORTH_SAYING * sent:
        return None
    why = f", {refused:.0f} of them refused" if refused else ""
    return (f"{100 * accepted / sent:.1f} % of the messages sent were recorded ({gaps:.0f} "
            f"missing{why}): the errors are judged on incomplete data")


def silent_followers(metrics: dict[str, Any]) -> tuple[int, ...]:
    """metrics.json's "silent_followers": followers whose estimates the run never saw."""
    raw = metrics.get("silent_followers")
    return tuple(i for i in raw if isinstance(i, int)) if isinstance(raw, list) else ()


def silent_text(silent: tuple[int, ...], n: int | None) -> str:
    names = ", ".join(str(i) for i in silent)
    over = "" if n is None else f"; estimator error over the other {n - len(silent)}"
    return f"follower{'s' if len(silent) > 1 else ''} {names} (0-based) sent no state{over}"


def law_line(info: dict[str, Any], metrics: dict[str, Any],
             launch: dict[str, Any]) -> str | None:
    """The law the followers flew (run.json) and its failures: in flight, the followers'
    `law_failures` counters as the flight ended (launch.json); in lock-step, metrics.json's."""
    law = info.get("law")
    if not isinstance(law, str):
        return None
    if launch:
        status = _dict(launch.get("status_at_stop") or launch.get("status"))
        counts = {name: _dict(c).get("law_failures") for name, c in status.items()
                  if name.startswith("follower-")}
    else:
        counts = {"lock-step": metrics.get("law_failures")}
    failed = {name: n for name, n in counts.items() if isinstance(n, int) and n > 0}
    if not failed:
        return f"{law} (no failure)" if launch or "law_failures" in metrics else law
    worst = max(failed, key=lambda k: failed[k])
    return (f"{law}: FAILED {sum(failed.values())} times, the vehicle held (most: {worst} "
            f"{failed[worst]}; its log has the traceback)")


def read_verdict(run_dir: Path, title: str, note: str = "") -> Verdict:
    metrics, info = _read(run_dir / "metrics.json"), _read(run_dir / "run.json")
    launch = _read(run_dir / "launch.json")
    error = metrics.get("error") if metrics else f"no metrics.json in {run_dir}"
    checks = tuple(
        Check(key, label, unit, _num(metrics.get(key)),
              _num(info.get(bound)) or PAPER_BOUNDS[bound])
        for key, label, unit, bound in BOUNDED
    )
    if "min_separation_m" in metrics:  # runs recorded before it was measured have none
        checks += (Check("min_separation_m", "closest approach", "m",
                         _num(metrics["min_separation_m"]),
                         _num(info.get("safety_distance_m")) or 1.0, floor=True),)
    live = launch.get("live_url")
    load = _dict(launch.get("load"))
    ticks = _dict(load.get("ticks"))
    return Verdict(
        title, run_dir, checks, None if error is None else str(error), metrics,
        process_lines(launch), link_summary(metrics),
        live if isinstance(live, str) and live else None,
        tuple(f + ("/" if f == "logs" else "") for f in FILES if (run_dir / f).exists()), note,
        bool(launch), load_line(load), overrun_line(ticks), memory_line(load),
        silent_followers(metrics), recording_line(metrics), launch_refusals(launch),
        law_line(info, metrics, launch), network_lines(metrics), liar_lines(launch),
        weather_lines(info, launch),
    )


def network_lines(metrics: dict[str, Any]) -> tuple[str, ...]:
    """One line per network fault of metrics.json's "net_faults"."""
    lines = []
    for f in metrics.get("net_faults") or []:
        if not isinstance(f, dict):
            continue
        back, sep = _num(f.get("recovery_s")), _num(f.get("min_separation_m"))
        lines.append(f"{f.get('label')}: " + ("never back inside the bounds" if back is None
                                              else f"back inside the bounds {back:.1f} s after")
                     + ("" if sep is None else f", closest approach {sep:.2f} m"))
    return tuple(lines)


def verdict_json(v: Verdict) -> dict[str, Any]:
    """metrics.json with a "verdict" object added, for scripts (`--json`)."""
    return {**v.metrics, "verdict": {
        "inside_bounds": v.inside,
        "error": v.error,
        "checks": {c.key: {"value": c.value, "bound": c.bound, "inside": c.inside}
                   for c in v.checks},
        "silent_followers": list(v.silent),
        "processes": list(v.processes),
        "refused": v.refused or {},
        "live_url": v.live_url,
        "load": v.load,
        "memory": v.memory,
        "late_ticks": v.ticks,
        "recording": v.recording,
        "law": v.law,
        "network": list(v.network),
        "liars": list(v.liars),
        "weather": list(v.weather),
        "run_dir": str(v.run_dir),
    }}


def headline(v: Verdict) -> Text:
    if v.error is not None:
        return Text.assemble((f"{v.title}: NO VERDICT", "bold red"), f" ({v.error})")
    steady = _num(v.metrics.get("steady_from_s"))
    window = "" if steady is None else f" (steady state from {steady:g} s)"
    if v.silent:  # the bounds hold for followers seen, which is not the swarm
        return Text.assemble((f"{v.title}: INCOMPLETE", "bold red"),
                             f" ({silent_text(v.silent, None)})")
    if v.inside:
        return Text.assemble((f"{v.title}: INSIDE the paper's bounds", "bold green"), window)
    return Text.assemble((f"{v.title}: OUTSIDE the paper's bounds", "bold red"), window)


def print_verdict(console: Console, v: Verdict) -> None:
    """At most about 12 lines: the answer first, then its evidence."""
    console.print(headline(v) + (Text(f"  [{v.note}]", style="yellow") if v.note else ""))
    grid = Table.grid(padding=(0, 2))
    for _ in range(4):
        grid.add_column()
    if v.error is None:
        for c in v.checks:
            over = "UNDER" if c.floor else "OVER"
            mark = Text("ok", style="green") if c.inside else Text(over, style="bold red")
            grid.add_row(f"  {c.label}", c.text(), c.bound_text(), mark)
        console.print(grid)
    settle = _num(v.metrics.get("settle_time_s"))
    rows = [] if v.error else [("settle time", "never" if settle is None else f"{settle:.1f} s")]
    rows += [("law", v.law)] if v.law else []
    rows += [("network", line) for line in v.network]
    rows += [("liars", line) for line in v.liars]
    rows += [("weather", line) for line in v.weather]
    if v.silent:
        n = len(v.metrics.get("followers") or {}) or None
        rows.append(("silent", silent_text(v.silent, n)))
    if v.networked:
        said = [*v.processes] or ["none died, restarted or failed"]
        refused = refusal_text(v.refused or {})
        rows.append(("processes", "; ".join(said + ([refused] if refused else []))))
    rows += [("links", v.links)] if v.links else []
    rows += [("recording", v.recording)] if v.recording else []
    rows += [("late ticks", v.ticks)] if v.ticks else []
    rows += [("CPU", v.load)] if v.load else []
    rows += [("memory", v.memory)] if v.memory else []
    rows += [("live view", v.live_url)] if v.live_url else []
    rows.append(("files", f"{v.run_dir}/ ({', '.join(v.files) or 'none'})"))
    for label, value in rows:
        console.print(Text(f"  {label:<13}{value}"), soft_wrap=True)


def announce(run_dir: Path, title: str, as_json: bool, note: str = "") -> Verdict:
    """The end of a command: the verdict on stdout; with `as_json`, the metrics and verdict
    as JSON on stdout (for scripts) and the verdict for people on stderr."""
    v = read_verdict(run_dir, title, note)
    if as_json:
        print(json.dumps(verdict_json(v), indent=2), flush=True)
    print_verdict(Console(stderr=as_json), v)
    return v


def add_json_argument(parser: Any) -> None:
    parser.add_argument(
        "--json", action="store_true",
        help="print metrics.json and the verdict as JSON on stdout (the verdict text on stderr)",
    )
