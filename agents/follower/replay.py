"""A follower's tick loop re-run from its input journal (agents.follower.journal).

`replay` feeds the same `LawRunner` the journal's calls in order and compares every
step's command, estimate, rate and published fields with what the run recorded, bit for
bit; the first that differs is named with its tick, time and what differed.  With
`check=False` (another law, other parameters: a counterfactual) nothing is compared and
the series of what it would have commanded is the answer, open loop.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agents.follower.journal import (
    JOIN,
    REGROUP,
    STEP,
    Mirror,
    fields_crc,
    read_peer,
    read_sample,
    read_target,
)
from agents.follower.journal_file import Frames
from agents.follower.membership import setup_for
from agents.follower.runner import LawRunner
from agents.law.interface import Law, Output
from agents.scenario.model import Scenario
from transport.law_fields import LawFields


@dataclass(frozen=True)
class Difference:
    """The first step whose result is not the recorded one."""

    tick: int  # steps replayed before it (control ticks and estimator steps)
    offset: int  # its frame's byte offset in the journal
    now_s: float
    why: str


@dataclass
class Series:
    """Per control tick: time, command and estimate (x + iy; nan-free: a failed step holds)."""

    t_s: list[float] = field(default_factory=list)
    u_m_s: list[complex] = field(default_factory=list)
    r_m: list[complex] = field(default_factory=list)
    recorded_u_m_s: list[complex] = field(default_factory=list)
    recorded_r_m: list[complex] = field(default_factory=list)
    regroups_s: list[float] = field(default_factory=list)


@dataclass
class Replay:
    """What replaying one journal found."""

    path: Path
    steps: int = 0
    difference: Difference | None = None
    stopped: str | None = None  # the journal ended early (a killed process): where
    series: Series = field(default_factory=Series)

    @property
    def reproduced(self) -> bool:
        return self.difference is None and self.steps > 0


def _result(done: list[Any] | None) -> tuple[complex, complex, complex, int] | None:
    if done is None:
        return None
    return complex(done[0], done[1]), complex(done[2], done[3]), complex(done[4], done[5]), done[6]


def compare(got: tuple[Output, LawFields] | None, done: list[Any] | None) -> str | None:
    """Why `got` is not the recorded `done`, or None if it is, bit for bit."""
    want = _result(done)
    if got is None or want is None:
        if got is None and want is None:
            return None
        return "the law failed in the replay" if got is None else "the law failed in the run"
    out, wire = got
    for name, a, b in (("command", out.u_m_s, want[0]), ("estimate", out.r_m, want[1]),
                       ("estimate rate", out.dr_m_s, want[2])):
        if a.real.hex() != b.real.hex() or a.imag.hex() != b.imag.hex():
            return f"{name} {a!r} in the replay, {b!r} in the run"
    if fields_crc(wire) != want[3]:
        return "the published fields differ"
    return None


def replay(path: Path, scenario: Scenario, law: Law[Any], check: bool = True) -> Replay:
    """Re-run the runner of follower `frames.header['index']` on its journal at `path`."""
    frames = Frames.open(path)
    index = int(frames.header["index"])
    runner = LawRunner(law, setup_for(scenario, index))
    found = Replay(path)
    targets, peers, joins = Mirror(read_target), Mirror(read_peer), Mirror(read_peer)
    for at, rec in frames.records():
        kind = rec[0]
        if kind == REGROUP:
            runner.regroup(setup_for(scenario, index, rec[1]))
            found.series.regroups_s.append(found.series.t_s[-1] if found.series.t_s else 0.0)
        elif kind == JOIN:
            runner.join(joins.apply(rec[2]), rec[1])
        elif kind == STEP:
            now_s, command, own, tdelta, pdelta, done = rec[1:]
            got = runner.step(now_s, command, read_sample(own), targets.apply(tdelta),
                              peers.apply(pdelta))
            if command:
                _keep(found.series, now_s, got, done)
            if check and found.difference is None:
                why = compare(got, done)
                if why is not None:
                    found.difference = Difference(found.steps, at, now_s, why)
            found.steps += 1
    found.stopped = frames.stopped
    return found


def _keep(series: Series, now_s: float, got: tuple[Output, LawFields] | None,
          done: list[Any] | None) -> None:
    want = _result(done)
    series.t_s.append(now_s)
    series.u_m_s.append(0j if got is None else got[0].u_m_s)
    series.r_m.append(series.r_m[-1] if got is None and series.r_m else
                      (0j if got is None else got[0].r_m))
    series.recorded_u_m_s.append(0j if want is None else want[0])
    series.recorded_r_m.append(series.recorded_r_m[-1] if want is None and series.recorded_r_m
                               else (0j if want is None else want[1]))


def journals(run_dir: Path, follower: int) -> Iterator[Path]:
    """Follower `follower`'s journals in a run directory, first process first (a restart
    writes the next part)."""
    folder = run_dir / "journal"
    first = folder / f"follower-{follower}.journal"
    if first.exists():
        yield first
    part = 2
    while (nxt := folder / f"follower-{follower}-part{part}.journal").exists():
        yield nxt
        part += 1
