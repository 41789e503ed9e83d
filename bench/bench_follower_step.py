"""A networked follower's per-step cost: its law and the platform around it (issue 15, 33).

python bench/bench_follower_step.py [--calls 2000] [--repeat 9]

Prints µs per call of what agents.follower.node does per step, for the paper's law
(agents.law.paper) in the paper's case and ring16 with both estimators:
- estimator step: the law advanced without a command (LawRunner.step, with the stand-ins
  for links not heard and the published fields checked and made wire-ready);
- control step: the same with the command, and the count of stale inputs;
- receive: a neighbour's FollowerState kept as the law reads it (Latest.peer);
- observe: one target observation folded into its track (Latest.observe).
Every call gets the same realistic state: a follower that has run a while, its
neighbours fresh, robust link sums published.  The figure is the best of --repeat rounds
of --calls calls (process CPU time: less disturbed by other load than wall time), so say
under what load it was measured.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from collections.abc import Callable
from typing import Any

from agents.follower.inputs import Latest
from agents.follower.runner import LawRunner
from agents.law.interface import Sample
from agents.law.paper import PaperLaw
from agents.loading.scenario_file import load_scenario
from agents.membership.follower_place import setup_for, stand_ins
from transport.messages import FollowerState, Header
from transport.network_schema import NetworkConfig


def _per_call_us(fn: Callable[[], Any], calls: int, repeat: int) -> float:
    for _ in range(calls):  # warm-up round, not counted
        fn()
    best = float("inf")
    for _ in range(repeat):
        start = time.process_time()
        for _ in range(calls):
            fn()
        best = min(best, time.process_time() - start)
    return best / calls * 1e6


def _message(j: int, receiver: int, now_s: float, runner: LawRunner) -> FollowerState:
    """Neighbour j's state as its law publishes it: its declared fields, sums towards us."""
    links = ((receiver, 0.3 * j, -0.2), (receiver + 1, 0.1, 0.1))
    rates = ((receiver, 0.01, 0.02), (receiver + 1, 0.0, 0.0))
    values = {"phi_m": (0.5, 0.5), "link_sums_m": links, "link_rates_m_s": rates,
              "rv_m_s": (0.1, 0.0), "vel_sums_m_s": links, "vel_rates_m_s2": rates}
    law = {name: values[name] for name in runner.declared}
    return FollowerState(Header(f"follower-{j}", 7, now_s - 0.004), j, (3.0 + 0.1 * j, 1.0),
                         (0.05, 0.0), (8.0, float(j)), (0.1, 1.0), (0.0, 1.0), now_s - 0.006,
                         law)


def _case(name: str, estimator: str, calls: int, repeat: int) -> dict[str, float]:
    scenario = dataclasses.replace(load_scenario(name), network=NetworkConfig(estimator))
    runner = LawRunner(PaperLaw.from_params({}, scenario), setup_for(scenario, 0))
    latest = Latest(0, runner.declared)
    setup, t = runner.setup, 10.0
    msgs = {j: _message(j, 0, t, runner) for j in setup.peers}
    for k, j in enumerate(setup.observed):
        for dt in (0.0, 0.02):
            latest.observe(setup, j, complex(k, 1.0 + dt), t - 0.02 + dt)
    for msg in msgs.values():
        latest.receive(msg, t)
    own = Sample(8.0 + 0.5j, 1j, t - 0.003)
    for step in (0.0, 0.005, 0.005, 0.005):  # a follower that has run: link sums, ages
        t += step
        runner.step(t, False, own, latest.targets, latest.peers)
    later, state = t + 0.005, runner.state
    target, msg = setup.observed[0], msgs[setup.neighbours[0]]

    def step(command: bool) -> Any:
        runner.state, runner.last_step_s = state, t  # every call: the same step
        peers = stand_ins(latest.peers, setup, runner.last_r, later)
        out = runner.step(later, command, own, latest.targets, peers)
        if command:
            latest.stale(setup, peers, later)
        return out

    stamps = iter(range(10**9))

    def observe() -> None:  # each a newer sample than the last: the filter runs
        latest.observe(setup, target, complex(0.5, 1.5), later + 0.01 * next(stamps))

    timings: list[tuple[str, Callable[[], Any]]] = [
        ("estimator step", lambda: step(False)),
        ("control step", lambda: step(True)),
        ("receive", lambda: latest.peer(msg)),
        ("observe", observe),
    ]
    print(f"<!-- {name}, {estimator}: follower 0, {len(setup.neighbours)} neighbours, "
          f"{len(setup.observed)} observed target(s), fields {sorted(runner.declared)} -->")
    assert runner.failures == 0
    return {label: _per_call_us(fn, calls, repeat) for label, fn in timings}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=9)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
          f"best of {args.repeat} x {args.calls} calls, process CPU time, µs per call")
    print("| case | estimator | per step | µs |")
    print("|---|---|---|---|")
    for name in ("paper", "ring16"):
        for estimator in ("robust", "paper"):
            for label, us in _case(name, estimator, args.calls, args.repeat).items():
                print(f"| {name} | {estimator} | {label} | {us:.2f} |")


if __name__ == "__main__":
    main()
