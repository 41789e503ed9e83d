"""The end of a recorded run: the same metrics.json, run.json, series files and figures as
`enclose simulate`, through the same `deploy.report.run_report.write_run_outputs`, read chunk by
chunk from the assembler's spills (deploy.recording.chunks): memory does not grow with the run."""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

from agents.analysis.metrics import Metrics
from agents.membership.ring_accuracy import PhaseReport, membership_phases
from agents.scenario.model import Scenario
from deploy.json_files import write_json_atomic
from deploy.recording.assembler import Assembly, RunAssembler, assembly_extra
from deploy.report.link_history import LINKS_CSV, LinkHistory
from deploy.report.run_report import write_run_outputs
from deploy.report.rundir import METRICS_FILE, RunInfo
from errors import DeployError

log = logging.getLogger(__name__)
RUN_KIND = "networked"
# A run whose last truth sample is this far short of the planned end was stopped early;
# its steady-state window is then judged on what was recorded.
_EARLY_STOP_FRACTION = 0.95


def judged_duration_s(asm: Assembly) -> float:
    """The duration the run is judged over (steady state = its second half by default)."""
    t_last = float(asm.t_s[-1])
    return asm.duration_s if t_last >= _EARLY_STOP_FRACTION * asm.duration_s else t_last


def write_final_outputs(
    run_dir: Path,
    scenario: Scenario,
    asm: RunAssembler,
    recorder_extra: dict[str, Any],
    membership: list[tuple[float, frozenset[int]]] | None = None,
    link_history: LinkHistory | None = None,
    figures: bool = True,
) -> Metrics | None:
    """Metrics, series files and (unless `figures` is False) figures of the run; None (and
    metrics.json with "error") if none."""
    began = time.monotonic()
    try:
        assembly = asm.assemble()
    except DeployError as exc:
        log.error("no metrics: %s", exc)
        write_error_metrics(run_dir, str(exc), {**recorder_extra,
                                                 "assembler_drops": dict(asm.drops)})
        return None
    if link_history is not None:  # before the figures: links.png is drawn from it
        link_history.write_csv(run_dir / LINKS_CSV, assembly.start_stamp_s)
    duration = judged_duration_s(assembly)
    info = RunInfo.from_scenario(scenario, RUN_KIND, duration)
    marks: list[float] = []
    phases = None
    if membership:
        changes = [(t - assembly.start_stamp_s, m) for t, m in membership]
        found = membership_phases(changes, float(assembly.t_s[-1]))
        marks = [p[0] for p in found[1:]]
        phases = PhaseReport(scenario, found)

    def extra() -> dict[str, Any]:  # once the series has been read through
        out = {**assembly_extra(assembly, asm.drops), **recorder_extra,
               "stopped_early": duration != assembly.duration_s}
        if phases is not None:
            out["membership"] = {"changes_s": marks, "phases": phases.result()}
        return out

    metrics = write_run_outputs(run_dir, assembly, info, extra, marks,
                                () if phases is None else (phases,), figures)
    log.info("run outputs written in %.2f s", time.monotonic() - began)
    return metrics


def write_error_metrics(run_dir: Path, reason: str, extra: dict[str, Any]) -> None:
    run_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(run_dir / METRICS_FILE, {"error": reason, "kind": RUN_KIND, **extra})
