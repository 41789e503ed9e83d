"""The end of `enclose sweep`, in the style of a run's verdict: how many cells finished, how
many stayed inside the paper's bounds (the worst one named), what failed, where the files are."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from rich.console import Console
from rich.text import Text

from deploy.sweep.spec import SweepSpec
from deploy.sweep.table import Row

BOUNDED = (("estimator_error_m", "m", "rho"), ("radius_error_m", "m", "rho"),
           ("angle_error", "", "delta"))


def overs(spec: SweepSpec, row: Row) -> list[tuple[float, str]]:
    """(value / bound, text) of each bounded metric of a finished cell at or over its bound."""
    out = []
    for key, unit, which in BOUNDED:
        bound = spec.eps_rho_m if which == "rho" else spec.eps_delta
        value = row.state.metrics.get(key)
        if value is None or value >= bound:
            shown = "none" if value is None else f"{value:.4g}{' ' + unit if unit else ''}"
            out.append((float("inf") if value is None else value / bound,
                        f"{key} {shown} >= {bound:g}"))
    return out


def print_sweep_verdict(console: Console, spec: SweepSpec, rows: Sequence[Row],
                        figures: Sequence[Path]) -> None:
    done = [r for r in rows if r.state.done]
    outside = {r.cell.name: overs(spec, r) for r in done}
    bad = {name: o for name, o in outside.items() if o}
    head = f"enclose sweep {spec.path.stem}: {len(done)}/{len(rows)} cells done"
    style = "bold green" if len(done) == len(rows) and not bad else "bold yellow"
    console.print(Text(head, style=style) + Text(
        f"; {len(done) - len(bad)} inside the paper's bounds, {len(bad)} outside"))
    if bad:
        name, worst = max(bad.items(), key=lambda kv: max(v for v, _ in kv[1]))
        console.print(f"  worst        {name}: {max(worst)[1]}", soft_wrap=True, markup=False)
    failed = [f"{r.cell.name} ({r.state.status})" for r in rows
              if not r.state.done and r.state.status != "pending"]
    if failed:
        console.print(f"  not done     {', '.join(failed)}", soft_wrap=True, markup=False)
    names = ["results.csv", "results.md", *(p.name for p in figures)]
    console.print(f"  files        {spec.out}/ ({', '.join(names)})", soft_wrap=True,
                  markup=False)
