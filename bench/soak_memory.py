"""A soak's memory per process and per role, from bench_soak.py's samples (issue "Hours,
not minutes"): each sample a dict of name, pid, t_s, flying, rss_mb, hwm_mb, cpu_s and
load_1min, taken each `--sample-s`."""

from __future__ import annotations

from typing import Any

import numpy as np


def slope_mb_h(t_s: list[float], rss_mb: list[float]) -> float | None:
    if len(t_s) < 3:
        return None
    return float(np.polyfit(np.asarray(t_s) / 3600.0, np.asarray(rss_mb), 1)[0])


def memory_table(samples: list[dict[str, Any]], settle_s: float) -> list[dict[str, Any]]:
    """Per process (its latest pid): growth after `settle_s`, slope, mean CPU, peak."""
    out = []
    for name in sorted({s["name"] for s in samples}, key=sort_key):
        mine = [s for s in samples if s["name"] == name]
        pid = mine[-1]["pid"]
        mine = [s for s in mine if s["pid"] == pid]
        flying = [s for s in mine if s["flying"] and s["t_s"] >= settle_s]
        before = [s["rss_mb"] for s in mine if s["t_s"] < settle_s]
        row: dict[str, Any] = {"name": name, "restarted": len({s["pid"] for s in samples
                                                               if s["name"] == name}) > 1,
                               "peak_mb": round(max(s["hwm_mb"] for s in mine), 1)}
        if len(flying) >= 2:
            first, last = flying[0], flying[-1]
            row.update(
                rss_start_mb=round(first["rss_mb"], 1), rss_end_mb=round(last["rss_mb"], 1),
                growth_pct=round(100 * (last["rss_mb"] - first["rss_mb"]) / first["rss_mb"], 2),
                slope_mb_h=_round(slope_mb_h([s["t_s"] for s in flying],
                                             [s["rss_mb"] for s in flying]), 2),
                cpu_pct=round(100 * (last["cpu_s"] - first["cpu_s"])
                              / max(1e-9, last["t_s"] - first["t_s"]), 1))
            if before:
                base, ceiling = max(before), max(s["rss_mb"] for s in flying)
                row["ceiling_growth_pct"] = round(100 * (ceiling - base) / base, 2)
        out.append(row)
    return out


def role_table(memory: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per role (follower, target, sim, ...): how many processes, the range of their RSS
    after the settling, and the worst growth and slope among them."""
    roles: dict[str, list[dict[str, Any]]] = {}
    for r in memory:
        if "rss_start_mb" in r:
            roles.setdefault(sort_key(r["name"])[0], []).append(r)
    return [{"role": role, "processes": len(rows),
             "rss_start_mb": [min(r["rss_start_mb"] for r in rows),
                              max(r["rss_start_mb"] for r in rows)],
             "rss_end_mb": [min(r["rss_end_mb"] for r in rows),
                            max(r["rss_end_mb"] for r in rows)],
             "growth_pct_max": max(r["growth_pct"] for r in rows),
             "ceiling_growth_pct_max": max((r["ceiling_growth_pct"] for r in rows
                                           if "ceiling_growth_pct" in r), default=None),
             "slope_mb_h_max": max((r["slope_mb_h"] for r in rows
                                    if r["slope_mb_h"] is not None), default=None),
             "peak_mb_max": max(r["peak_mb"] for r in rows)}
            for role, rows in roles.items()]


def load_range(samples: list[dict[str, Any]], settle_s: float) -> dict[str, float] | None:
    """The machine's 1-minute load average over the flight after `settle_s`."""
    loads = {s["t_s"]: s["load_1min"] for s in samples
             if s["flying"] and s["t_s"] >= settle_s and s.get("load_1min") is not None}
    if not loads:
        return None
    v = list(loads.values())
    return {"min": min(v), "mean": round(sum(v) / len(v), 2), "max": max(v)}


def sort_key(name: str) -> tuple[str, int]:
    role, _, idx = name.rpartition("-")
    return (role, int(idx)) if idx.isdigit() else (name, -1)


def _round(v: float | None, digits: int) -> float | None:
    return None if v is None else round(v, digits)
