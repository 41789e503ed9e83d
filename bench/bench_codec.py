"""Message-path micro-benchmark (issue 15): µs per call of encode, decode and the receive path.

    python bench/bench_codec.py [--calls 20000] [--repeats 7]

For FollowerState (a robust ring follower: the paper law's link sums and rates on 2
links; "FollowerState rv": the same with the second-order estimator's rv_m_s and
velocity-stage sums and rates),
TargetObservation and TruthSnapshot (16 followers, 2 targets), and the low-rate
ProcessStatus (1 Hz per process), ClockProbe (4 Hz per host) and RunControl (twice a run),
prints the time per call of
- `encode(msg)`;
- `decode(payload)`;
- the whole receive path: `encode(msg)` plus `LinkDecoder(limits=DEFAULT_LIMITS,
  senders=...).decode()` of a `Received` on the message's key (codec, key checks, clock mapping,
  plausibility checks, sequence tracking, per-link tally), as a follower/recorder runs it;
- `encode_reference` and `decode_reference`: the schema walk alone, what a message without
  a fast twin (transport.codec_fast.TWINS) costs, so that a twin is kept only where it pays.
Each figure is the best of `repeats` runs of `calls` calls, in CPU time of this process
(process_time: other processes on the machine disturb it less than wall time), the least
disturbed by other load on the machine; the load average is printed with them.
Single process, no network; runs in a few seconds.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from collections.abc import Callable

from transport.access import sender_ids
from transport.bus import Received
from transport.codec import decode, decode_reference, encode, encode_reference
from transport.key_exprs import SwarmKeys
from transport.link_stats import LinkDecoder
from transport.message_checks import DEFAULT_LIMITS
from transport.messages import (
    ClockProbe,
    FollowerState,
    Header,
    Message,
    ProcessStatus,
    RunControl,
    TargetObservation,
    TruthSnapshot,
)

KEYS = SwarmKeys("bench")
N_FOLLOWERS = 16
SENDERS = sender_ids(N_FOLLOWERS, 2, 2)  # as every process decodes: the scenario's senders only


def follower_state(seq: int, now_s: float) -> FollowerState:
    return FollowerState(
        Header("follower-3", seq, now_s - 0.002), 3, (1.25, -2.5), (0.01, 0.02),
        (20.0, 3.5), (1.5, -0.5), (1.4, -0.6), now_s - 0.004,
        {"link_sums_m": ((2, 0.125, -0.25), (4, -0.5, 0.75)),
         "link_rates_m_s": ((2, 0.001, 0.002), (4, -0.003, 0.0))})


def follower_state_rv(seq: int, now_s: float) -> FollowerState:
    msg = follower_state(seq, now_s)
    return dataclasses.replace(msg, law={
        **msg.law, "rv_m_s": (0.25, -0.5),
        "vel_sums_m_s": ((2, 0.0125, -0.025), (4, -0.05, 0.075)),
        "vel_rates_m_s2": ((2, 0.5, 0.25), (4, -0.125, 0.0))})


def target_observation(seq: int, now_s: float) -> TargetObservation:
    return TargetObservation(Header("sim-0", seq, now_s - 0.002), 3, 1, (4.5, -1.25),
                             now_s - 0.003, 0.05)


def truth_snapshot(seq: int, now_s: float) -> TruthSnapshot:
    pos3 = tuple((float(i), -float(i), 10.0) for i in range(N_FOLLOWERS))
    vel3 = tuple((0.5, 0.25 * i, 0.0) for i in range(N_FOLLOWERS))
    return TruthSnapshot(Header("sim-0", seq, now_s - 0.002), 12.5, pos3, vel3,
                         ((1.0, 2.0), (3.0, 4.0)), ((0.1, 0.0), (0.0, 0.1)))


def process_status(seq: int, now_s: float) -> ProcessStatus:
    counters = {f"counter_{k}": k for k in range(24)}  # a follower's status, about its size
    return ProcessStatus(Header("follower-3", seq, now_s - 0.002), "follower", 3, "running",
                         counters, "")


def clock_probe(seq: int, now_s: float) -> ClockProbe:
    echoes = tuple((f"router-{k}", now_s - 0.01 * k, now_s - 0.005 * k) for k in range(3))
    return ClockProbe(Header("router-0", seq, now_s - 0.002), now_s - 100.0, echoes)


def run_control(seq: int, now_s: float) -> RunControl:
    return RunControl(Header("launcher-0", seq, now_s - 0.002), "start", now_s + 2.0, 60.0)


CASES: dict[str, tuple[Callable[[int, float], Message], str]] = {
    "FollowerState": (follower_state, KEYS.follower_state(3)),
    "FollowerState rv": (follower_state_rv, KEYS.follower_state(3)),
    "TargetObservation": (target_observation, KEYS.sensor_targets(3)),
    "TruthSnapshot": (truth_snapshot, KEYS.truth()),
    "ProcessStatus": (process_status, KEYS.status("follower", 3)),
    "ClockProbe": (clock_probe, KEYS.clock("router", 0)),
    "RunControl": (run_control, KEYS.control()),
}


def best_us(run: Callable[[], None], calls: int, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.process_time()
        run()
        best = min(best, time.process_time() - t0)
    return best / calls * 1e6


def measure(make: Callable[[int, float], Message], key: str, calls: int,
            repeats: int) -> dict[str, float]:
    now_s = time.time()
    msgs = [make(k, now_s) for k in range(calls)]
    payloads = [encode(m) for m in msgs]
    assert decode(payloads[0]) == msgs[0]

    def run_encode() -> None:
        for m in msgs:
            encode(m)

    def run_decode() -> None:
        for p in payloads:
            decode(p)

    def run_receive() -> None:
        # A fresh decoder per run; each message has its own sequence number: all new.
        dec = LinkDecoder(limits=DEFAULT_LIMITS, senders=SENDERS)
        for m in msgs:
            if dec.decode(Received(key, encode(m), now_s)) is None:
                raise AssertionError(f"dropped: {dec.dropped}")

    def run_encode_reference() -> None:
        for m in msgs:
            encode_reference(m)

    def run_decode_reference() -> None:
        for p in payloads:
            decode_reference(p)

    return {"encode": best_us(run_encode, calls, repeats),
            "decode": best_us(run_decode, calls, repeats),
            "receive": best_us(run_receive, calls, repeats),
            "encode_ref": best_us(run_encode_reference, calls, repeats),
            "decode_ref": best_us(run_decode_reference, calls, repeats)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--calls", type=int, default=20000)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    print(f"load average (1 min) {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
          f"best of {args.repeats} x {args.calls} calls")
    print(f"{'message':<18} {'encode µs':>10} {'decode µs':>10} {'receive µs':>11}"
          f" {'walk enc µs':>12} {'walk dec µs':>12}")
    for name, (make, key) in CASES.items():
        r = measure(make, key, args.calls, args.repeats)
        print(f"{name:<18} {r['encode']:>10.2f} {r['decode']:>10.2f} {r['receive']:>11.2f}"
              f" {r['encode_ref']:>12.2f} {r['decode_ref']:>12.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
