"""Late ticks and errors of a finished run over time, for bench_soak.py.

Both are read per minute of experiment time (the followers' and the simulator's
`overruns`/`ticks` counters from their statuses in recording.mcap; the worst follower's
|e_rho|, |e_delta|, |r - LAP| at each sample of series.parquet), then summed or pooled
over any span of whole minutes: the table's windows, and the spans the issue compares
("the last 10 minutes no worse than the first steady 10").
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

ERROR_COLUMNS = ("e_rho_m", "e_delta", "est_err_m")
Span = tuple[float, float]  # [start, end) in minutes of experiment time


def late_per_minute(out: Path, start_stamp_s: float) -> dict[str, dict[int, list[int]]]:
    """Per role ("follower", "sim"): minute -> [late, ticks] summed over its processes,
    from the differences of each process's counters between minutes."""
    from collections import Counter

    from deploy.recording.resume import read_messages
    from transport.messages import ProcessStatus

    last: dict[str, dict[int, tuple[int, int]]] = {}  # process -> minute -> counters
    for _key, msg, _recv_s in read_messages(out / "recording.mcap", Counter()):
        if not isinstance(msg, ProcessStatus) or msg.role not in ("follower", "sim"):
            continue
        c = msg.counters
        if "ticks" not in c or "overruns" not in c:
            continue
        m = math.floor((msg.header.stamp_s - start_stamp_s) / 60.0)
        key = f"{msg.role}-{msg.index}"
        last.setdefault(key, {})[m] = (int(c["overruns"]), int(c["ticks"]))
    minutes: dict[str, dict[int, list[int]]] = {}
    for key, per in last.items():
        before = (0, 0)
        for m in sorted(per):
            late, ticks = per[m]
            if ticks < before[1]:  # a restarted process counts from zero again
                before = (0, 0)
            acc = minutes.setdefault(key.rpartition("-")[0], {}).setdefault(m, [0, 0])
            acc[0] += late - before[0]
            acc[1] += ticks - before[1]
            before = (late, ticks)
    return minutes


def late_over(per_minute: dict[int, list[int]], span: Span) -> list[int]:
    """[late, ticks] over the minutes of `span`."""
    rows = [v for m, v in per_minute.items() if span[0] <= m < span[1]]
    return [sum(r[0] for r in rows), sum(r[1] for r in rows)]


def series_batches(out: Path, rows: int = 4096) -> Iterator[dict[str, np.ndarray]]:
    """series.parquet in batches of columns; series.csv where there is no Parquet file."""
    parquet = out / "series.parquet"
    if parquet.exists():
        import pyarrow.parquet as pq

        for batch in pq.ParquetFile(parquet).iter_batches(batch_size=rows):
            yield {c: batch.column(c).to_numpy() for c in batch.schema.names}
        return
    with open(out / "series.csv") as f:
        names = f.readline().strip().split(",")
        while lines := list(itertools.islice(f, rows)):
            data = np.loadtxt(lines, delimiter=",", ndmin=2)
            yield {c: data[:, k] for k, c in enumerate(names)}


def worst_errors(out: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Each sample's time (s) and, per error, the worst follower's magnitude at it: one
    float per sample and error (a 60-minute run at 20 Hz: 72 000 rows)."""
    t_parts: list[np.ndarray] = []
    parts: dict[str, list[np.ndarray]] = {kind: [] for kind in ERROR_COLUMNS}
    for batch in series_batches(out):
        t_parts.append(batch["t_s"])
        for kind in ERROR_COLUMNS:
            names = [c for c in batch if re.fullmatch(rf"[a-z]+\d+_{kind}", c)]
            parts[kind].append(np.nanmax(np.abs(np.column_stack([batch[c] for c in names])),
                                         axis=1))
    if not t_parts:
        return np.zeros(0), {kind: np.zeros(0) for kind in ERROR_COLUMNS}
    return np.concatenate(t_parts), {k: np.concatenate(v) for k, v in parts.items()}


def errors_over(t_s: np.ndarray, worst: dict[str, np.ndarray],
                span: Span) -> tuple[dict[str, float], dict[str, float]]:
    """Over the samples of `span`: per error, the max (what the verdict compares) and the
    95th percentile (a transient moves the max alone; a swarm that got worse, both)."""
    inside = (t_s >= 60.0 * span[0]) & (t_s < 60.0 * span[1])
    peak: dict[str, float] = {}
    p95: dict[str, float] = {}
    for kind, values in worst.items():
        v = values[inside]
        v = v[~np.isnan(v)]  # an infinite error stays the worst
        if v.size:
            peak[kind], p95[kind] = float(v.max()), float(np.percentile(v, 95))
    return peak, p95


def verdict(first: dict[str, float], last: dict[str, float], bounds: dict[str, float]) -> bool:
    """Errors no worse: each at most 1.25 times its first value, or inside the paper's bound."""
    return all(last.get(k, 0.0) <= max(1.25 * first.get(k, 0.0), bounds[k])
               for k in ERROR_COLUMNS)


def late_ok(first: list[int], last: list[int]) -> bool:
    """Late ticks no worse: at most double the first rate plus 0.1 % of ticks."""
    rate = [late / ticks if ticks else 0.0 for late, ticks in (first, last)]
    return rate[1] <= 2 * rate[0] + 0.001
