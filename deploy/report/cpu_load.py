"""What the run cost the machine: CPU and peak memory per process, how busy the machine was.

Issue 15's figures (and any accuracy figure) depend on machine load: a swarm that fills
both cores overruns its ticks and its errors are no longer the design's.  The launcher
samples every child's CPU time (/proc/<pid>/stat) and the machine's busy time
(/proc/stat) a few times a minute; `CpuSampler.summary` gives each process's mean CPU,
in % of one core, over a window (the steady half of the run), the machine's busy %, in %
of all its cores, and its mean 1-minute load average.  Linux only: elsewhere every
reading is None and the summary is empty.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

PROC = Path("/proc")
TICKS_PER_S = float(os.sysconf("SC_CLK_TCK")) if hasattr(os, "sysconf") else 100.0


def stat_fields(text: str) -> list[str]:
    """The fields of a /proc/<pid>/stat line after the command name: [0] is field 3
    (state), [11] and [12] utime and stime, [16] nice, [38] the scheduling policy.  The
    command name (field 2) may hold spaces and parentheses: split after its last ')'."""
    return text.rpartition(")")[2].split()


def process_cpu_s(pid: int, proc: Path = PROC) -> float | None:
    """User + system CPU seconds of process `pid` so far (all its threads); None if gone."""
    try:
        text = (proc / str(pid) / "stat").read_text()
    except OSError:
        return None
    fields = stat_fields(text)
    try:
        return (int(fields[11]) + int(fields[12])) / TICKS_PER_S
    except (IndexError, ValueError):
        return None


def process_status_kb(pid: int, field: str, proc: Path = PROC) -> int | None:
    """A kB figure of /proc/<pid>/status (`VmRSS`, `VmHWM`...); None if gone or absent."""
    try:
        for line in (proc / str(pid) / "status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        return None
    return None


def process_peak_rss_mb(pid: int, proc: Path = PROC) -> float | None:
    """The most resident memory process `pid` has held so far (VmHWM), MB; None if gone."""
    kb = process_status_kb(pid, "VmHWM", proc)
    return None if kb is None else kb / 1024.0


def machine_ticks(proc: Path = PROC) -> tuple[int, int] | None:
    """(busy, total) clock ticks of all CPUs since boot; None when unreadable."""
    try:
        first = (proc / "stat").read_text().split("\n", 1)[0].split()
        values = [int(v) for v in first[1:9]]  # user nice system idle iowait irq softirq steal
    except (OSError, ValueError):
        return None
    idle = values[3] + values[4]
    return sum(values) - idle, sum(values)


def load_1min(proc: Path = PROC) -> float | None:
    try:
        return float((proc / "loadavg").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return None


def busy_pct(first: tuple[int, int], last: tuple[int, int]) -> float | None:
    """How busy the machine was between two `machine_ticks` readings, in %; None if no
    tick passed between them."""
    if last[1] <= first[1]:
        return None
    return 100.0 * (last[0] - first[0]) / (last[1] - first[1])


@dataclass
class _Window:
    """Running sums over the samples at or after `from_s` (nothing per sample is kept: the
    launcher samples every second for as long as the run lasts)."""

    from_s: float
    cpu: dict[str, list[float]] = field(default_factory=dict)  # name -> [cpu s, wall s]
    machine_first: tuple[int, int] | None = None  # busy, total ticks
    machine_last: tuple[int, int] | None = None
    machine_samples: int = 0
    loads: list[float] = field(default_factory=lambda: [0.0, 0.0])  # sum, count

    def add_cpu(self, name: str, before: tuple[float, int, float], t_s: float, pid: int,
                cpu_s: float) -> None:
        t0, pid0, c0 = before
        if t0 >= self.from_s and pid0 == pid and t_s > t0 and cpu_s >= c0:
            sums = self.cpu.setdefault(name, [0.0, 0.0])
            sums[0] += cpu_s - c0
            sums[1] += t_s - t0

    def add_machine(self, t_s: float, busy: int, total: int, load: float | None) -> None:
        if t_s < self.from_s:
            return
        self.machine_first = self.machine_first or (busy, total)
        self.machine_last = (busy, total)
        self.machine_samples += 1
        if load is not None:
            self.loads[0] += load
            self.loads[1] += 1


@dataclass
class CpuSampler:
    """Readings over time; `sample` is cheap (a few /proc reads per process).  `summary`
    answers for the windows named here (`windows_from_s`), kept as running sums."""

    proc: Path = PROC
    windows_from_s: tuple[float, ...] = (0.0,)
    peak_rss_mb: dict[str, float] = field(default_factory=dict)  # name -> max over its pids
    # name -> its latest (t_s, pid, cpu_s); a restart shows as a new pid (CPU from 0)
    latest: dict[str, tuple[float, int, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._windows = {t: _Window(t) for t in self.windows_from_s}

    def sample(self, t_s: float, pids: dict[str, int | None]) -> None:
        for name, pid in pids.items():
            cpu = None if pid is None else process_cpu_s(pid, self.proc)
            if pid is not None and cpu is not None:
                self.add_cpu(name, t_s, pid, cpu)
            peak = None if pid is None else process_peak_rss_mb(pid, self.proc)
            if peak is not None:
                self.peak_rss_mb[name] = max(peak, self.peak_rss_mb.get(name, 0.0))
        ticks = machine_ticks(self.proc)
        if ticks is not None:
            load = load_1min(self.proc)
            for w in self._windows.values():
                w.add_machine(t_s, ticks[0], ticks[1], load)

    def add_cpu(self, name: str, t_s: float, pid: int, cpu_s: float) -> None:
        """One reading of process `name`: CPU seconds `cpu_s` of `pid` at `t_s`."""
        before = self.latest.get(name)
        self.latest[name] = (t_s, pid, cpu_s)
        if before is not None:
            for w in self._windows.values():
                w.add_cpu(name, before, t_s, pid, cpu_s)

    def summary(self, from_s: float, cores: int | None = None) -> dict[str, object]:
        """{"process_cpu_pct": {name: % of a core}, "machine_busy_pct", "load_1min", "cores"}
        over the samples at or after `from_s` (one of `windows_from_s`; only what was
        sampled twice or more), and "process_peak_rss_mb" {name: MB} over the whole run."""
        w = self._windows.get(from_s)
        if w is None:
            raise ValueError(f"no CPU window from {from_s}: windows {sorted(self._windows)}")
        out: dict[str, object] = {}
        per = {name: round(100.0 * c / wall, 1) for name, (c, wall) in sorted(w.cpu.items())
               if wall > 0}
        if per:
            out["process_cpu_pct"] = per
        if self.peak_rss_mb:
            out["process_peak_rss_mb"] = {k: round(v, 1)
                                          for k, v in sorted(self.peak_rss_mb.items())}
        first, last = w.machine_first, w.machine_last
        busy = busy_pct(first, last) if w.machine_samples >= 2 and first and last else None
        if busy is not None:
            out["machine_busy_pct"] = round(busy, 1)
            if w.loads[1]:
                out["load_1min"] = round(w.loads[0] / w.loads[1], 2)
            out["cores"] = cores or os.cpu_count() or 1
        return out


# A machine this busy queues every process for a core: latencies, late ticks and the
# errors they cause are then the machine's (docs/large-swarms.md, "What a run costs").
SATURATED_PCT = 95.0


def start_saturation_note(since: tuple[int, int] | None, now: tuple[int, int] | None,
                          load: float | None, processes: int) -> str | None:
    """Why a start-up failed, when the machine was saturated between the `machine_ticks`
    readings `since` (the spawns) and `now`: its processes then starve one another, and a
    simulator starved for seconds looks like a vehicle that does not answer.  None if the
    machine had room, or was not read."""
    busy = None if since is None or now is None else busy_pct(since, now)
    if busy is None or busy < SATURATED_PCT:
        return None
    load_text = "" if load is None else f", load {load:.0f}"
    return (f"The machine was {busy:.0f} % busy from the spawns on ({os.cpu_count() or 1} "
            f"cores{load_text}, {processes} processes of this run): they need more CPU than "
            "it has, and the start-up failed for it.  Try a smaller swarm, a lower [run] "
            "rate_hz, or a machine with more free cores; what a machine holds: "
            "docs/large-swarms.md, bench/bench_floor.py.")


def _by_role(per: dict[str, float], each: str, unit: str, targets_at_most: bool) -> list[str]:
    """Followers as mean and max (`each` after the mean), the other processes one by one,
    the targets as one figure (their mean, or their max when `targets_at_most`)."""
    followers = {k: v for k, v in per.items() if k.startswith("follower-")}
    parts = []
    if followers:
        worst = max(followers, key=followers.__getitem__)
        mean = sum(followers.values()) / len(followers)
        parts.append(f"followers {mean:.1f} {each} (max {followers[worst]:.1f} {worst})")
    parts += [f"{k} {v:.0f} {unit}" for k, v in sorted(per.items())
              if k not in followers and not k.startswith("target-")]
    targets = [v for k, v in per.items() if k.startswith("target-")]
    if targets and targets_at_most:
        parts.append(f"targets {max(targets):.0f} {unit} at most")
    elif targets:
        parts.append(f"targets {sum(targets) / len(targets):.0f} {unit} each")
    return parts


def load_line(cpu: dict[str, object]) -> str | None:
    """One line for the verdict: followers' mean and max, the others, the machine."""
    per = cpu.get("process_cpu_pct")
    if not isinstance(per, dict) or not per:
        return None
    parts = _by_role(per, "% of a core each", "%", targets_at_most=False)
    busy = cpu.get("machine_busy_pct")
    if isinstance(busy, int | float):
        load = cpu.get("load_1min")
        tail = f", load {load:g}" if isinstance(load, int | float) else ""
        parts.append(f"machine {busy:.0f} % busy ({cpu.get('cores')} cores{tail})")
        if busy >= SATURATED_PCT:
            parts[-1] += ": saturated, so the errors measure the machine as well as the run"
    return "; ".join(parts)


def memory_line(load: dict[str, object]) -> str | None:
    """One line for the verdict: the followers' peak resident memory, mean and max, and the
    other processes' (the targets' largest)."""
    per = load.get("process_peak_rss_mb")
    if not isinstance(per, dict) or not per:
        return None
    return "; ".join(_by_role(per, "MB each at peak", "MB", targets_at_most=True))


def _late_ticks(counters: object) -> tuple[int, int] | None:
    """(late, ticks) from a process's status counters; None when it counts no ticks."""
    if not isinstance(counters, dict):
        return None
    late, ticks = counters.get("overruns"), counters.get("ticks")
    if not isinstance(late, int) or not isinstance(ticks, int) or ticks <= 0:
        return None
    return late, ticks


def overrun_summary(status: dict[str, object]) -> dict[str, object]:
    """Followers' late control ticks from their last status counters (launch.json "status"):
    {"overruns", "ticks", "overrun_pct", "worst", "worst_pct"}; empty when none reported."""
    total_late = total_ticks = 0
    worst, worst_pct = None, -1.0
    for name, counters in sorted(status.items()):
        counted = _late_ticks(counters) if name.startswith("follower-") else None
        if counted is None:
            continue
        late, ticks = counted
        total_late, total_ticks = total_late + late, total_ticks + ticks
        if 100.0 * late / ticks > worst_pct:
            worst, worst_pct = name, 100.0 * late / ticks
    if total_ticks == 0:
        return {}
    return {"overruns": total_late, "ticks": total_ticks,
            "overrun_pct": round(100.0 * total_late / total_ticks, 2),
            "worst": worst, "worst_pct": round(worst_pct, 2), **_sim_overruns(status)}


def _sim_overruns(status: dict[str, object]) -> dict[str, object]:
    """The simulator's late ticks: when it falls behind, the vehicles fly behind real time
    and the ring's errors are the machine's (ring32 on 2 cores: a third of them late)."""
    counted = _late_ticks(status.get("sim-0"))
    if counted is None:
        return {}
    late, ticks = counted
    return {"sim_overruns": late, "sim_ticks": ticks,
            "sim_overrun_pct": round(100.0 * late / ticks, 2)}


def overrun_line(summary: dict[str, object]) -> str | None:
    if not summary:
        return None
    line = (f"{summary['overrun_pct']:.2f} % of follower ticks late "
            f"({summary['overruns']} of {summary['ticks']}; worst {summary['worst']} "
            f"{summary['worst_pct']:.2f} %)")
    if "sim_ticks" in summary:
        line += (f"; simulator {summary['sim_overrun_pct']:.2f} % "
                 f"({summary['sim_overruns']} of {summary['sim_ticks']})")
    return line
