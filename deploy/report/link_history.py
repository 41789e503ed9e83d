"""Link health over time, from the followers' periodic status counters: `links.csv`.

Each follower publishes its per-link counters (`transport.link_stats`) about once a
second.  Between two successive statuses of one receiver, for each link into it:
- `delivered`: unique messages received / sequence numbers the sender used (its seq
  span), i.e. 1 - loss over that interval;
- `age_mean_ms`: mean age at delivery of the messages received in the interval.
A restarted receiver starts its counters again from zero: its first interval after
that has no value.  `age_p50_ms` and `age_p99_ms` are the receiver's whole-run figures
at that time.  Times are seconds of the receiver's status stamp on the bus clock; the
writer turns them into experiment time.

A link is silent when its receiver's latest status is SILENT_AFTER_S older than the newest
follower status seen: judged against the stream, not the wall clock, so a recorder that
drains seconds behind the bus does not call every link silent (its lag is reported apart,
`recorder_behind_s` in progress.json).

The samples go to a temporary file as they come (a ring of 64 followers makes ~250 a
second); memory keeps each link's latest.  `read_links_csv` reads a long run's links.csv
back as at most `LINK_POINTS` points in all: a link's intervals in bins, each bin its worst
(lowest delivered ratio, highest age), so that a dip shows however long the run.
"""

from __future__ import annotations

import csv
import math
import tempfile
from collections import Counter
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from transport.messages import ProcessStatus

LINKS_CSV = "links.csv"
COLUMNS = ("t_s", "link", "rx", "offered", "delivered", "age_mean_ms", "age_p50_ms",
           "age_p99_ms")
SILENT_AFTER_S = 3.0  # a receiver this far behind the newest follower status is silent
LINK_POINTS = 400_000  # points of links.png in all (7 columns each): ~22 MB at most


@dataclass(frozen=True)
class LinkSample:
    stamp_s: float
    link: str  # "f0->f2", "sensor->f1"
    rx: int
    offered: int | None
    delivered: float | None  # over the interval since the previous sample
    age_mean_ms: float | None  # idem
    age_p50_ms: float | None
    age_p99_ms: float | None


def _ratio(num: float, den: float) -> float | None:
    return num / den if den > 0 and num >= 0 else None


def _ms(us: int | None) -> float | None:
    return None if us is None else us / 1000.0


class LinkHistory:
    """Every follower status's link counters, as interval samples per link (on disk)."""

    def __init__(self, spill_dir: Path | None = None) -> None:
        self._spool: IO[str] = tempfile.TemporaryFile("w+", dir=spill_dir)  # noqa: SIM115
        self._last: dict[str, Mapping[str, int]] = {}  # link -> counters of its last sample
        self._latest: dict[str, LinkSample] = {}
        # Newest follower status stamp, with or without link counters: the reference
        # against which a receiver counts as silent (the stream's time, not ours).
        self._newest_s = -math.inf

    def add(self, status: ProcessStatus) -> None:
        self._newest_s = max(self._newest_s, status.header.stamp_s)
        c = status.counters
        for name in sorted(k[3:] for k in c if k.startswith("rx_") and not k.startswith("rx_dup")):
            link = f"{name}->f{status.index}"
            now = self._counters(c, name)
            before = self._last.get(link)
            delivered = age = None
            if before is not None:
                delivered = _ratio(now["rx"] - before["rx"], now["seq"] - before["seq"])
                n = now["age_n"] - before["age_n"]
                age = _ratio((now["age_sum_us"] - before["age_sum_us"]) / 1000.0, n)
            if delivered is not None:
                delivered = min(delivered, 1.0)  # copies and reordering at the span's edges
            sample = LinkSample(status.header.stamp_s, link, now["rx"],
                                now["seq"] - now["seq0"] + 1 if now["seq"] >= 0 else None,
                                delivered, age, _ms(c.get(f"age_p50_us_{name}")),
                                _ms(c.get(f"age_p99_us_{name}")))
            self._last[link] = now
            self._latest[link] = sample
            # The fields in their declared order (as `samples` reads them back), by hand:
            # dataclasses.astuple deep-copies, and was a quarter of ring64's recorder.
            self._spool.write(",".join(map(_exact, (
                sample.stamp_s, sample.link, sample.rx, sample.offered, sample.delivered,
                sample.age_mean_ms, sample.age_p50_ms, sample.age_p99_ms))) + "\n")

    def samples(self) -> Iterator[LinkSample]:
        """Every sample so far, in arrival order."""
        self._spool.seek(0)
        for line in self._spool:
            stamp, link, rx, offered, *rest = line.rstrip("\n").split(",")
            yield LinkSample(float(stamp), link, int(rx), None if offered == "" else int(offered),
                             *(None if v == "" else float(v) for v in rest))
        self._spool.seek(0, 2)

    def close(self) -> None:
        self._spool.close()

    @staticmethod
    def _counters(c: Mapping[str, int], name: str) -> dict[str, int]:
        return {"rx": int(c.get(f"rx_{name}", 0)), "seq": int(c.get(f"seq_last_{name}", -1)),
                "seq0": int(c.get(f"seq_first_{name}", 0)),
                "age_n": int(c.get(f"age_n_{name}", 0)),
                "age_sum_us": int(c.get(f"age_sum_us_{name}", 0))}

    def summary(self) -> dict[str, Any]:
        """For progress.json: the worst link now (small: the launcher's board reads it).

        Silent: the receiver stopped reporting while others went on.  If every receiver
        stopped (or our own input did), none is: `recorder_behind_s` tells that.
        """
        latest = list(self._latest.values())
        fresh = [s for s in latest if self._newest_s - s.stamp_s <= SILENT_AFTER_S]
        silent = [s.link for s in latest if self._newest_s - s.stamp_s > SILENT_AFTER_S]
        ratios = [(s.delivered, s.link) for s in fresh if s.delivered is not None]
        ages = [(s.age_mean_ms, s.link) for s in fresh if s.age_mean_ms is not None]
        worst_ratio = min(ratios, default=None)
        worst_age = max(ages, default=None)
        return {
            "count": len(latest),
            "silent": sorted(silent),
            "min_delivered": None if worst_ratio is None else round(worst_ratio[0], 4),
            "min_delivered_link": None if worst_ratio is None else worst_ratio[1],
            "max_age_ms": None if worst_age is None else round(worst_age[0], 2),
            "max_age_link": None if worst_age is None else worst_age[1],
        }

    def write_csv(self, path: Path, start_stamp_s: float) -> None:
        with open(path, "w", newline="") as f:
            out = csv.writer(f)
            out.writerow(COLUMNS)
            for s in self.samples():
                out.writerow([f"{s.stamp_s - start_stamp_s:.3f}", s.link, s.rx,
                              _cell(s.offered), _cell(s.delivered), _cell(s.age_mean_ms),
                              _cell(s.age_p50_ms), _cell(s.age_p99_ms)])


def _cell(v: float | int | None) -> str:
    return "" if v is None else f"{v:.6g}"


def _exact(v: float | int | str | None) -> str:
    return "" if v is None else repr(v) if isinstance(v, float) else str(v)


LinkColumns = dict[str, NDArray[np.float64]]


def read_links_csv(path: Path, max_points: int = LINK_POINTS) -> dict[str, LinkColumns]:
    """links.csv as link -> column -> values (NaN where empty); {} if there is none.  Past
    `max_points` rows in all, each link's rows are taken in bins: the bin's last time,
    lowest delivered ratio and highest ages."""
    try:
        with open(path, newline="") as f:
            per_link = Counter(row["link"] for row in csv.DictReader(f))
        if not per_link:
            return {}
        cap = max(1, max_points // len(per_link))
        bins = {link: math.ceil(count / cap) for link, count in per_link.items()}
        with open(path, newline="") as f:
            return _binned(csv.DictReader(f), per_link, bins)
    except (OSError, ValueError, KeyError):
        return {}


_WORST = {"delivered": np.fmin, "age_mean_ms": np.fmax, "age_p50_ms": np.fmax,
          "age_p99_ms": np.fmax}


def _binned(rows: Iterator[dict[str, str]], counts: Mapping[str, int],
            bins: Mapping[str, int]) -> dict[str, LinkColumns]:
    names = [k for k in COLUMNS if k != "link"]
    out = {link: {k: np.full(math.ceil(n / bins[link]), np.nan) for k in names}
           for link, n in counts.items()}
    seen: Counter[str] = Counter()
    for row in rows:
        link = row["link"]
        at, cols = seen[link] // bins[link], out[link]
        seen[link] += 1
        for k in names:
            v = float(row[k]) if row.get(k) else math.nan
            worst = _WORST.get(k)
            cols[k][at] = v if worst is None else worst(cols[k][at], v)
    return out
