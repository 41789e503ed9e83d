"""A networked follower's per-step cost: the reference logic against its fast twin (issue 15).

python bench/bench_follower_step.py [--calls 2000] [--repeat 9]

Prints µs per call of estimator_tick, follower_tick, peer_view and observe_target, for
agents.follower_logic (before: numpy 2-vectors) and agents.follower_fast (after: complex
numbers), for the paper's case and ring16 with both estimators.  Every call gets the same
realistic state: a follower that has run a while, its neighbours fresh, robust link sums
published.  The figure is the best of --repeat rounds of --calls calls (process CPU time:
less disturbed by other load than wall time), so say under what load it was measured.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from agents import follower_fast as fast
from agents import follower_logic as ref
from agents.scenario.file import load_scenario
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


def _message(j: int, receiver: int, now_s: float, robust: bool) -> FollowerState:
    links = ((receiver, 0.3 * j, -0.2, 0.01, 0.02), (receiver + 1, 0.1, 0.1, 0.0, 0.0))
    return FollowerState(Header(f"follower-{j}", 7, now_s - 0.004), j, (3.0 + 0.1 * j, 1.0),
                         (0.05, 0.0), (0.5, 0.5), (8.0, float(j)), (0.1, 1.0), (0.0, 1.0),
                         now_s - 0.006, links if robust else ())


def _case(name: str, estimator: str, calls: int, repeat: int) -> dict[str, tuple[float, float]]:
    scenario = dataclasses.replace(load_scenario(name), network=NetworkConfig(estimator))
    setup = ref.FollowerSetup.from_scenario(scenario, 0)
    fsetup = fast.FastSetup.of(setup)
    robust, t = estimator == "robust", 10.0
    msgs = {j: _message(j, 0, t, robust) for j in fsetup.peers}
    out: dict[str, tuple[float, float]] = {}
    timings: list[tuple[str, Callable[[], Any], Callable[[], Any]]] = []
    r_mem, f_mem = ref.FollowerMemory(), fast.FollowerMemory()
    for k, j in enumerate(setup.observed):
        for dt in (0.0, 0.02):
            r_mem = ref.observe_target(r_mem, setup, j, np.array([k, 1.0 + dt]), t - 0.02 + dt)
            f_mem = fast.observe_target(f_mem, fsetup, j, complex(k, 1.0 + dt), t - 0.02 + dt)
    r_peers = {j: ref.peer_view(m, 0) for j, m in msgs.items()}
    f_peers = {j: fast.peer_view(m, 0) for j, m in msgs.items()}
    for step in (0.0, 0.005, 0.005, 0.005):  # a follower that has run: link sums, ages
        t += step
        r_mem = ref.estimator_tick(r_mem, setup, r_peers, t)
        f_mem = fast.estimator_tick(f_mem, fsetup, f_peers, t)
    later, own = t + 0.005, (np.array([8.0, 0.5]), np.array([0.0, 1.0]), t - 0.003)
    r_own, f_own = ref.Sample(*own), fast.Sample(complex(*own[0]), complex(*own[1]), own[2])
    target, msg = setup.observed[0], msgs[setup.neighbours[0]]
    timings = [
        ("estimator_tick", lambda: ref.estimator_tick(r_mem, setup, r_peers, later),
         lambda: fast.estimator_tick(f_mem, fsetup, f_peers, later)),
        ("follower_tick", lambda: ref.follower_tick(r_mem, setup, r_own, r_peers, later),
         lambda: fast.follower_tick(f_mem, fsetup, f_own, f_peers, later)),
        ("peer_view", lambda: ref.peer_view(msg, 0), lambda: fast.peer_view(msg, 0)),
        ("observe_target",
         lambda: ref.observe_target(r_mem, setup, target, np.array([0.5, 1.5]), later),
         lambda: fast.observe_target(f_mem, fsetup, target, complex(0.5, 1.5), later)),
        ("link_flows", lambda: ref.link_flows(r_mem, setup),
         lambda: fast.link_flows(f_mem, fsetup)),
    ]
    print(f"<!-- {name}, {estimator}: follower 0, {len(setup.neighbours)} neighbours, "
          f"{len(setup.observed)} observed target(s) -->")
    for label, before, after in timings:
        out[label] = (_per_call_us(before, calls, repeat), _per_call_us(after, calls, repeat))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=9)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
          f"best of {args.repeat} x {args.calls} calls, process CPU time, µs per call")
    print("| case | estimator | function | before (follower_logic) | after (follower_fast) "
          "| speed-up |")
    print("|---|---|---|---|---|---|")
    for name in ("paper", "ring16"):
        for estimator in ("robust", "paper"):
            for label, (before, after) in _case(name, estimator, args.calls, args.repeat).items():
                print(f"| {name} | {estimator} | {label} | {before:.1f} | {after:.2f} "
                      f"| {before / after:.1f}x |")


if __name__ == "__main__":
    main()
