"""`enclose replay RUN_DIR follower-K`: re-run a follower's law on its input journal.

Without a change of law it must reproduce the run's commands, estimates and published
fields bit for bit, or it names the first step that differs and why (exit 1).  With
`--law`, `--law-param` or `--set SECTION.KEY=VALUE` it is a counterfactual: what that
law or those parameters would have commanded on the same inputs, open loop, drawn beside
the run (RUN_DIR/replay-follower-K.png).  `--all` replays every follower.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.follower.journal_file import Frames
from agents.follower.journal_replay import Replay, journals, replay
from agents.loading.law_loader import make_law
from agents.loading.scenario_file import load_scenario
from agents.scenario.model import Scenario
from agents.shell.law_args import LawOptions, add_law_arguments, apply_law_arguments, toml_value
from agents.shell.network_args import NetworkOptions, add_network_arguments, apply_network_arguments
from errors import EncloseError, JournalError, ScenarioError


def register(sub: Any) -> None:
    p = sub.add_parser("replay", help="re-run a follower's law on its input journal: "
                       "reproduce the run, or ask what another law would have done")
    p.add_argument("run_dir", type=Path, help="the run directory (enclose run --out)")
    p.add_argument("follower", nargs="?", default=None, help="follower-K (0-based K)")
    p.add_argument("--all", action="store_true", help="replay every follower")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="another value of a scenario parameter (e.g. gains.k_e=4): a "
                        "counterfactual (repeatable)")
    p.add_argument("--figure", type=Path, default=None,
                   help="the counterfactual's figure (default: RUN_DIR/replay-follower-K.png)")
    add_law_arguments(p)
    p.set_defaults(func=run)


@dataclass(frozen=True)
class ReplayOptions:
    """What to ask of a journal besides reproducing it: another law or parameters (a
    counterfactual, drawn into `figure`, default RUN_DIR/replay-follower-K.png)."""

    law: LawOptions = dataclasses.field(default_factory=LawOptions)
    sets: tuple[str, ...] = ()  # SECTION.KEY=VALUE
    figure: Path | None = None

    @property
    def counterfactual(self) -> bool:
        return bool(self.law.law or self.law.params or self.sets)

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> ReplayOptions:
        return cls(LawOptions.from_namespace(args), tuple(args.set), args.figure)


@dataclass(frozen=True)
class FollowerReplay:
    """One journal replayed (`found`), and the counterfactual on its inputs, if asked."""

    found: Replay
    asked: Replay | None = None
    figure: Path | None = None


def run_scenario(header: dict[str, Any]) -> Scenario:
    """The scenario, law and network the follower flew, from its journal's header."""
    parser = argparse.ArgumentParser()
    add_network_arguments(parser)
    add_law_arguments(parser)
    law = ["--law", header["law"]] if header.get("law") else []
    for key, value in header.get("law_params") or []:
        law += ["--law-param", f"{key}={value}"]
    args = parser.parse_args([*(header.get("network") or []), *law])
    scenario = load_scenario(header.get("scenario"), whole_run=False)
    scenario = apply_network_arguments(scenario, NetworkOptions.from_namespace(args))
    return apply_law_arguments(scenario, LawOptions.from_namespace(args))


def with_sets(scenario: Scenario, sets: list[str]) -> Scenario:
    """`scenario` with each SECTION.KEY=VALUE applied (ScenarioError naming a bad one)."""
    for text in sets:
        m = re.fullmatch(r"\s*(\w+)\.(\w+)\s*=(.*)", text)
        section = getattr(scenario, m.group(1), None) if m else None
        if m is None or not dataclasses.is_dataclass(section) or isinstance(section, type):
            raise ScenarioError("--set", f"must be SECTION.KEY=VALUE, got {text!r}")
        key = m.group(2)
        if key not in {f.name for f in dataclasses.fields(section)}:
            raise ScenarioError(f"--set {m.group(1)}.{key}", "no such parameter")
        changed: Any = dataclasses.replace(section, **{key: toml_value(m.group(3).strip())})
        new: dict[str, Any] = {m.group(1): changed}
        scenario = dataclasses.replace(scenario, **new)
    return scenario


def _follower(text: str | None) -> int:
    m = re.fullmatch(r"follower-(\d+)", text or "")
    if m is None:
        raise EncloseError(f"name the follower as follower-K, got {text!r} (or use --all)")
    return int(m.group(1))


def replay_journals(run_dir: Path, k: int, opts: ReplayOptions) -> list[FollowerReplay]:
    """Replay follower k's journals (a restarted follower wrote one per process); with
    another law or parameters, also what they would have commanded on the first one."""
    paths = list(journals(run_dir, k))
    if not paths:
        raise EncloseError(f"follower-{k}: no journal in {run_dir / 'journal'} (a run "
                           "with --no-journal, or not a run directory)")
    out = []
    for path in paths:
        scenario = run_scenario(Frames.open(path).header)
        t0 = time.perf_counter()
        found = replay(path, scenario, make_law(scenario))
        _say(found, k, time.perf_counter() - t0)
        if opts.counterfactual and path == paths[0]:
            out.append(_counterfactual(path, scenario, found, run_dir, k, opts))
        else:
            out.append(FollowerReplay(found))
    return out


def replay_follower(run_dir: Path, k: int, opts: ReplayOptions) -> bool:
    """Replay follower k, print the verdict; True if every journal reproduced."""
    return all(r.found.reproduced for r in replay_journals(run_dir, k, opts))


def _counterfactual(path: Path, scenario: Scenario, found: Replay, run_dir: Path, k: int,
                    opts: ReplayOptions) -> FollowerReplay:
    """The other law or parameters on the same inputs, open loop, drawn beside the run."""
    other = with_sets(apply_law_arguments(scenario, opts.law), list(opts.sets))
    asked = replay(path, other, make_law(other), check=False)
    law_words = ["law " + opts.law.law] if opts.law.law else []
    label = " ".join([*law_words, *(f"{k_}={v}" for k_, v in opts.law.params), *opts.sets])
    from deploy.report.replay_figure import counterfactual_figure

    out = opts.figure or run_dir / f"replay-follower-{k}.png"
    drawn = counterfactual_figure(found.series, asked.series, found.start_s, run_dir, k,
                                  label, out)
    apart = max((abs(a - b) for a, b in zip(found.series.u_m_s, asked.series.u_m_s,
                                            strict=False)), default=0.0)
    print(f"  {label}, open loop: its command up to {apart:.3f} m/s from the run's; "
          f"figure: {drawn}")
    return FollowerReplay(found, asked, drawn)


def _say(found: Replay, k: int, took_s: float) -> None:
    rate = found.steps / took_s if took_s > 0 else 0.0
    head = f"follower-{k} ({found.path.name}): {found.steps} steps, {rate:.0f} steps/s"
    if found.difference is not None:
        d = found.difference
        print(f"{head}: NOT reproduced: step {d.tick} (t = {d.now_s:.3f} s, frame at byte "
              f"{d.offset}): {d.why}")
    elif found.steps == 0:
        print(f"{head}: nothing to replay (the law never ran)")
    else:
        print(f"{head}: reproduced bit for bit")
    if found.stopped:
        print(f"  the journal stops early: {found.stopped}")
    jump = found.jumps.largest
    if jump is not None:
        print(f"  largest command jump of the steady part {jump.size_m_s:.3f} m/s at "
              f"{jump.t_s - found.start_s:.2f} s, {jump.before_m_s:.3f} -> "
              f"{jump.after_m_s:.3f}: "
              f"{jump.inputs}")


def run(args: argparse.Namespace) -> int:
    run_dir: Path = args.run_dir
    opts = ReplayOptions.from_namespace(args)
    try:
        if args.all:
            folder = run_dir / "journal"
            ks = sorted({int(p.name.split("-")[1].split(".")[0])
                         for p in folder.glob("follower-*.journal")})
            if not ks:
                raise EncloseError(f"no journal in {folder}")
            results = {k: replay_follower(run_dir, k, opts) for k in ks}
            bad = [f"follower-{k}" for k, ok in results.items() if not ok]
            print("run reproduced: every follower" if not bad else
                  f"run NOT reproduced: {', '.join(bad)}")
            return 1 if bad else 0
        return 0 if replay_follower(run_dir, _follower(args.follower), opts) else 1
    except JournalError as exc:
        print(f"damaged or foreign journal: {exc}")
        return 2
