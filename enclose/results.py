"""`enclose.Run`: one run directory read back (`enclose.load_run`), lock-step or networked.

Reads what `enclose simulate` and `enclose run` write (deploy.report.rundir,
deploy.launch.launch_end, deploy.recording): metrics.json, run.json, launch.json,
series.parquet or series.csv, links.csv, the figures and the recording. Older run
directories lack some of these: what is missing reads empty.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deploy.json_files import read_json
from deploy.report.verdict import Verdict, read_verdict
from errors import ConfigError

if TYPE_CHECKING:  # pandas is imported when a table is first read
    import pandas as pd

# name in Run.paths -> file or folder of a run directory
FILES: dict[str, str] = {
    "metrics": "metrics.json",
    "run": "run.json",
    "launch": "launch.json",
    "series": "series.csv",
    "series_parquet": "series.parquet",
    "links": "links.csv",
    "performance": "performance.png",
    "trajectory": "trajectory.png",
    "links_figure": "links.png",
    "recording": "recording.mcap",
    "scenario": "scenario.toml",
    "logs": "logs",
}
MARKERS = ("metrics.json", "series.csv", "launch.json")  # one of them: a run directory


@dataclass(frozen=True)
class Run:
    """A finished run: its metrics and verdict, its series and links as tables, its files.

    `exit_code` is the command's (None when read back from a directory)."""

    run_dir: Path
    metrics: dict[str, Any] = field(repr=False)
    verdict: Verdict = field(repr=False)
    launch: dict[str, Any] = field(repr=False)
    info: dict[str, Any] = field(repr=False)
    exit_code: int | None = None

    @property
    def kind(self) -> str:
        """"lockstep" (enclose simulate) or "networked" (enclose run)."""
        kind = self.info.get("kind")
        return "networked" if self.launch or kind == "networked" else str(kind or "lockstep")

    @property
    def inside(self) -> bool:
        """Inside the paper's bounds (every follower seen, every error under its bound)."""
        return self.verdict.inside

    @cached_property
    def series(self) -> pd.DataFrame:
        """The series (columns deploy.report.rundir.series_columns), indexed by time t_s: from
        series.parquet (full precision, quick for long runs) where the run has one, else
        from series.csv."""
        parquet = self.run_dir / FILES["series_parquet"]
        if parquet.exists():
            return _table(parquet, index="t_s")
        return _table(self.run_dir / FILES["series"], index="t_s")

    @cached_property
    def links(self) -> pd.DataFrame:
        """links.csv (networked runs: delivery and age per link over time); else empty."""
        return _table(self.run_dir / FILES["links"])

    @property
    def events(self) -> list[dict[str, Any]]:
        """What happened to the processes (deaths, restarts, faults), from launch.json."""
        events = self.launch.get("events")
        return [e for e in events if isinstance(e, dict)] if isinstance(events, list) else []

    @property
    def paths(self) -> dict[str, Path]:
        """The files the run wrote, by name (FILES): only those that exist."""
        found = {name: self.run_dir / f for name, f in FILES.items()}
        return {name: p for name, p in found.items() if p.exists()}

    @property
    def figures(self) -> list[Path]:
        return [p for p in self.paths.values() if p.suffix == ".png"]

    def __str__(self) -> str:
        state = "no verdict" if self.verdict.error else (
            "inside the paper's bounds" if self.inside else "outside the paper's bounds")
        return f"{self.kind} run {self.info.get('name', '?')} in {self.run_dir}: {state}"


def load_run(run_dir: str | Path, exit_code: int | None = None) -> Run:
    """A run directory written by `enclose simulate`, `enclose run` or a sweep cell."""
    path = Path(run_dir).resolve()
    if not path.is_dir():
        raise ConfigError("run_dir", f"{path} is not a directory")
    if not any((path / marker).exists() for marker in MARKERS):
        raise ConfigError("run_dir", f"{path} holds none of {', '.join(MARKERS)}")
    return Run(
        run_dir=path,
        metrics=read_json(path / FILES["metrics"]) or {},
        verdict=read_verdict(path, path.name),
        launch=read_json(path / FILES["launch"]) or {},
        info=read_json(path / FILES["run"]) or {},
        exit_code=exit_code,
    )


def _table(path: Path, index: str | None = None) -> pd.DataFrame:
    import pandas as pd

    if not path.exists():
        return pd.DataFrame()
    try:
        frame = pd.read_parquet(path) if path.suffix == ".parquet" else pd.read_csv(path)
    except (OSError, ValueError) as exc:
        raise ConfigError(path.name, f"cannot be read as a table: {exc}") from exc
    return frame.set_index(index) if index and index in frame.columns else frame
