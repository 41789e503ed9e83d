"""What a wake-up and a Zenoh message cost this machine (issue 15: the floor of a big ring).

Prints CPU per iteration (not wall time) of
  1. a timed sleep of 1, 5 and 20 ms and its wake-up (the followers' Ticker), and what one
     fixed piece of Python work costs back to back and right after each pause, a sleep or a
     busy wait (a follower's tick is such work after a 20-ms pause): three FollowerStates
     built, encoded and through a follower's receive path (decode, the transport's checks,
     the link tallies: transport.link_stats.LinkDecoder);
  2. a pipe ping-pong between two busy processes (an event wake-up);
  3. zenoh-python `put` of a 160-byte payload at 200 Hz, to a subscriber in the same
     session and to one in another process over TCP on 127.0.0.1 (default transport and
     `lowlatency`): the caller's thread CPU, and the whole process's (Zenoh's threads too).
Zenoh here is configured as everywhere in enclose: multicast scouting off, explicit
127.0.0.1 endpoints.  Run: python bench/bench_wake_cost.py [--n 400]   (about 30 s)
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from collections.abc import Callable

import zenoh

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from transport.access import sender_ids
from transport.bus import Received
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.link_stats import LinkDecoder
from transport.message_checks import DEFAULT_LIMITS
from transport.messages import FollowerState, Header

PORT = 17_999
PAYLOAD = b"x" * 160


def sleep_cost(period_s: float, n: int) -> float:
    c0, nxt = time.process_time(), time.perf_counter()
    for _ in range(n):
        nxt += period_s
        time.sleep(max(0.0, nxt - time.perf_counter()))
    return (time.process_time() - c0) / n


def receive_work() -> Callable[[], None]:
    """Three fresh FollowerStates through a follower's receive path, per call."""
    keys, decoder, seq = SwarmKeys("wake"), LinkDecoder(limits=DEFAULT_LIMITS,
                                                         senders=sender_ids(4, 2)), [0]
    law = {"link_sums_m": ((0, 0.5, -0.25), (2, 0.1, 0.2)),
           "link_rates_m_s": ((0, 0.01, 0.0), (2, -0.02, 0.01))}

    def run() -> None:
        now_s = time.time()
        for j in (1, 2, 3):
            msg = FollowerState(Header(f"follower-{j}", seq[0], now_s), j, (1.0, 2.0),
                                (0.1, 0.2), (9.0, -3.0), (0.5, 0.5), (0.4, 0.6), now_s, law)
            if decoder.decode(Received(keys.follower_state(j), encode(msg), now_s)) is None:
                raise AssertionError(f"dropped: {decoder.dropped}")
        seq[0] += 1
    return run


def cold_cost(work: Callable[[], None], pause_s: float, spin: bool, n: int) -> float:
    """Median thread CPU of `work` right after a sleep (or a busy wait) of `pause_s`; back
    to back when `pause_s` is 0."""
    work()
    used = []
    for _ in range(n):
        if pause_s <= 0.0:
            pass
        elif spin:
            end = time.perf_counter() + pause_s
            while time.perf_counter() < end:
                pass
        else:
            time.sleep(pause_s)
        t0 = time.thread_time_ns()
        work()
        used.append(time.thread_time_ns() - t0)
    return sorted(used)[n // 2] * 1e-9


def pipe_cost(n: int) -> tuple[float, float]:
    """(parent, child) CPU per round trip of a one-byte pipe ping-pong."""
    r1, w1 = os.pipe()
    r2, w2 = os.pipe()
    pid = os.fork()
    if pid == 0:
        c0 = time.process_time()
        for _ in range(n):
            os.read(r1, 1)
            os.write(w2, b"x")
        os.write(w2, str(time.process_time() - c0).encode().ljust(32))
        os._exit(0)
    c0 = time.process_time()
    for _ in range(n):
        os.write(w1, b"x")
        os.read(r2, 1)
    parent = time.process_time() - c0
    child = float(os.read(r2, 32).decode())
    os.waitpid(pid, 0)
    return parent / n, child / n


def config(listen: bool, lowlatency: bool) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    side = "listen" if listen else "connect"
    conf.insert_json5(f"{side}/endpoints", f'["tcp/127.0.0.1:{PORT}"]')
    if lowlatency:
        conf.insert_json5("transport/unicast/lowlatency", "true")
        conf.insert_json5("transport/unicast/qos/enabled", "false")
    return conf


def put_cost(session: zenoh.Session, n: int) -> tuple[float, float]:
    """(caller thread, whole process) CPU per put at 200 Hz, sleep included in the latter."""
    pub = session.declare_publisher("bench/wake")
    time.sleep(0.5)  # the subscriber's interest reaches us
    thread_s, c0 = 0.0, time.process_time()
    for _ in range(n):
        t = time.thread_time()
        pub.put(PAYLOAD)
        thread_s += time.thread_time() - t
        time.sleep(0.005)
    total = time.process_time() - c0
    pub.undeclare()
    return thread_s / n, total / n


def subscriber(seconds: float, lowlatency: bool) -> None:
    with zenoh.open(config(True, lowlatency)) as session:
        sub = session.declare_subscriber("bench/**", zenoh.handlers.RingChannel(256))
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            while sub.try_recv() is not None:
                pass
            time.sleep(0.005)


def remote(n: int, lowlatency: bool) -> tuple[float, float]:
    seconds = n * 0.006 + 4.0
    child = subprocess.Popen([sys.executable, __file__, "--subscriber", str(seconds)]
                             + (["--lowlatency"] if lowlatency else []))
    try:
        time.sleep(1.0)
        with zenoh.open(config(False, lowlatency)) as session:
            return put_cost(session, n)
    finally:
        child.wait(timeout=seconds + 10)


def local(n: int) -> tuple[float, float]:
    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", "[]")
    with zenoh.open(conf) as session:
        sub = session.declare_subscriber("bench/**", zenoh.handlers.RingChannel(4096))
        out = put_cost(session, n)
        sub.undeclare()
        return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=400)
    parser.add_argument("--subscriber", type=float, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--lowlatency", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.subscriber is not None:
        subscriber(args.subscriber, args.lowlatency)
        return
    us = 1e6
    for period in (0.001, 0.005, 0.020):
        n = min(args.n, int(4.0 / period))
        print(f"timed sleep {period * 1e3:4.0f} ms + wake-up: {sleep_cost(period, n) * us:6.1f} "
              "us CPU per iteration", flush=True)
    work, n = receive_work(), min(args.n, 200)
    warm = cold_cost(work, 0.0, False, 4 * n)
    print(f"3 states received, back to back:         {warm * us:6.1f} us", flush=True)
    for period, spin in ((0.001, False), (0.005, False), (0.020, False), (0.020, True)):
        cold = cold_cost(work, period, spin, n)
        pause = "busy wait" if spin else "sleep"
        print(f"3 states received after a {period * 1e3:2.0f}-ms {pause:9s}: {cold * us:6.1f} us "
              f"({cold / warm:.1f}x)", flush=True)
    parent, child = pipe_cost(20 * args.n)
    print(f"pipe ping-pong, two busy processes: {parent * us:5.1f} + {child * us:5.1f} us CPU "
          "per round trip", flush=True)
    thread, total = local(args.n)
    print(f"put, subscriber in the same session: {thread * us:6.1f} us caller thread, "
          f"{total * us:6.1f} us process per iteration (5-ms sleep included)", flush=True)
    for low in (False, True):
        thread, total = remote(args.n, low)
        print(f"put, subscriber in another process{' (lowlatency)' if low else ''}: "
              f"{thread * us:6.1f} us caller thread, {total * us:6.1f} us process per "
              "iteration (5-ms sleep included)", flush=True)


if __name__ == "__main__":
    main()
