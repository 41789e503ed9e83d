"""A follower's tick loop re-run from its input journal (agents.follower.journal).

`replay` feeds the same `LawRunner` the journal's calls in order and compares every
step's command, estimate, rate and published fields with what the run recorded, bit for
bit; the first that differs is named with its tick, time and what differed.  With
`check=False` (another law, other parameters: a counterfactual) nothing is compared and
the series of what it would have commanded is the answer, open loop.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agents.follower.journal import (
    JOIN,
    REBASE,
    REGROUP,
    STEP,
    WINDOW,
    Mirror,
    PeerCodec,
    read_sample,
    read_target,
    result_crcs,
)
from agents.follower.journal_file import Frames
from agents.follower.replay_explain import JumpWatch
from agents.follower.runner import LawRunner
from agents.law.interface import Law, Output
from agents.membership.follower_place import setup_for
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
    regroups_s: list[float] = field(default_factory=list)


@dataclass
class Replay:
    """What replaying one journal found."""

    path: Path
    steps: int = 0
    difference: Difference | None = None
    stopped: str | None = None  # the journal ended early (a killed process): where
    series: Series = field(default_factory=Series)
    jumps: JumpWatch = field(default_factory=JumpWatch)
    # The experiment's start and stop on the follower's clock (the run's control words);
    # the time axis of figures and the window of the largest jump
    start_s: float = -math.inf
    stop_s: float = math.inf

    def steady_s(self, steady_from_s: float | None) -> float:
        """Where the run's metrics start judging (its steady part), on this clock: the
        window of the largest command jump, like the run's `command_jump_m_s`."""
        if steady_from_s is not None:
            return self.start_s + steady_from_s
        return self.start_s + 0.5 * (self.stop_s - self.start_s)

    @property
    def reproduced(self) -> bool:
        return self.difference is None and self.steps > 0


_PARTS = ("command", "estimate or its rate", "published fields")


def compare(got: tuple[Output, LawFields] | None, done: list[int] | None) -> str | None:
    """Why `got` is not the recorded result `done` (journal.result_crcs), or None if it
    is, bit for bit."""
    if got is None or done is None:
        if got is None and done is None:
            return None
        return "the law failed in the replay" if got is None else "the law failed in the run"
    mine = result_crcs(got)
    assert mine is not None
    wrong = [name for name, a, b in zip(_PARTS, mine, done, strict=True) if a != b]
    if not wrong:
        return None
    out = got[0]
    return (f"{' and '.join(wrong)} not the run's (the replay's: command {out.u_m_s:.6g}, "
            f"estimate {out.r_m:.6g})")


def replay(path: Path, scenario: Scenario, law: Law[Any], check: bool = True) -> Replay:
    """Re-run the runner of follower `frames.header['index']` on its journal at `path`."""
    frames = Frames.open(path)
    index = int(frames.header["index"])
    runner = LawRunner(law, setup_for(scenario, index))
    found = Replay(path)
    codec = PeerCodec(frames.header.get("fields") or [])
    targets, peers, joins = Mirror(read_target), Mirror(codec.decode), Mirror(codec.decode)
    for at, rec in frames.records():
        kind = rec[0]
        if kind == REGROUP:
            runner.regroup(setup_for(scenario, index, rec[1]))
            found.series.regroups_s.append(found.series.t_s[-1] if found.series.t_s else 0.0)
        elif kind == JOIN:
            runner.join(joins.apply(rec[2]), rec[1])
        elif kind == REBASE:
            runner.continue_estimate()
        elif kind == WINDOW:
            found.start_s, found.stop_s = rec[1], rec[2]
            runner.window(rec[1], rec[2])  # the origin of the law's t_s, as in the run
        elif kind == STEP:
            now_s, command, own, tdelta, pdelta, done = rec[1:]
            mine, tmap, pmap = read_sample(own), targets.apply(tdelta), peers.apply(pdelta)
            found.jumps.arrived(entry[0] for entry in pdelta[1])
            got = runner.step(now_s, command, mine, tmap, pmap)
            if command:
                _keep(found.series, now_s, got)
                if found.steady_s(scenario.run.steady_from_s) <= now_s < found.stop_s:
                    found.jumps.tick(now_s, found.series.u_m_s[-1], mine, tmap, pmap)
            if check and found.difference is None:
                why = compare(got, done)
                if why is not None:
                    found.difference = Difference(found.steps, at, now_s, why)
            found.steps += 1
    found.stopped = frames.stopped
    return found


def _keep(series: Series, now_s: float, got: tuple[Output, LawFields] | None) -> None:
    """A control tick's command (0: a failed law holds) and estimate (the last one held)."""
    series.t_s.append(now_s)
    series.u_m_s.append(0j if got is None else got[0].u_m_s)
    held = series.r_m[-1] if series.r_m else 0j
    series.r_m.append(held if got is None else got[0].r_m)


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
