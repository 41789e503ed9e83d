"""Zenoh bus between real OS processes on 127.0.0.1: delivery, stamps, bad input, liveliness."""

from __future__ import annotations

import contextlib
import math
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from functools import partial
from pathlib import Path

import msgpack
import pytest

from tests.integration import runs
from transport.bus import Bus, wait_until_alive
from transport.codec import encode
from transport.decoder import Decoder
from transport.key_exprs import SwarmKeys
from transport.messages import FollowerState, ProcessStatus, Stamper
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import LINK_BUFFER_BYTES, ZenohConfig, loopback_endpoint

pytestmark = pytest.mark.integration
REPO = Path(__file__).resolve().parents[2]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# runs.wait_for, polled faster: round trips on loopback take a fraction of a millisecond.
wait_for = partial(runs.wait_for, period_s=0.002)


@contextlib.contextmanager
def echo_peer(swarm: str, endpoint: str) -> Iterator[subprocess.Popen[bytes]]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "tests.integration.transport_peer", "--swarm", swarm,
         "--listen", endpoint, "--max-s", "60"], cwd=REPO)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)


def state(stamper: Stamper, x: float = 1.0) -> FollowerState:
    return FollowerState(stamper.header(), 0, (x, 2.0), (0.1, 0.2), (5.0, 6.0),
                         (0.5, 0.6), (0.7, 0.8), time.time(), {"phi_m": (0.0, 0.0)})


@pytest.mark.timeout(60)
def test_two_processes_exchange_stamped_states_and_survive_garbage() -> None:
    swarm, port = f"it{os.getpid()}", free_port()
    keys = SwarmKeys(swarm)
    with echo_peer(swarm, loopback_endpoint(port)) as proc, \
            ZenohBus(ZenohConfig(connect=(loopback_endpoint(port),))) as bus:
        typed: Bus = bus  # ZenohBus implements the Bus protocol (checked by mypy)
        alive = typed.watch_alive(keys.all_alive())
        wait_until_alive(alive, {keys.alive("echo", 0)}, timeout_s=20)
        echoes, statuses = bus.subscribe(keys.follower_state(1)), bus.subscribe(keys.all_status())
        pub = bus.declare_publisher(keys.follower_state(0))
        wait_for(pub.matched, 10, "echo subscriber to match")

        nan_state = msgpack.unpackb(encode(state(Stamper("x"))))
        nan_state[6] = [math.nan, 0.0]
        pub.put(b"\xc1 not msgpack")
        # Five times Zenoh's batch (LINK_BUFFER_BYTES): fragmented on the way, whole on arrival.
        pub.put(b"\xc1" + bytes(5 * LINK_BUFFER_BYTES))
        pub.put(bytes(msgpack.packb(nan_state)))
        stamper, decoder = Stamper("follower-0"), Decoder()
        sent = state(stamper, x=42.0)
        pub.put(encode(sent))

        got: list[FollowerState] = []
        counters: dict[str, int] = {}

        def echo_and_counts_seen() -> bool:
            for inbound in decoder.drain(echoes):
                assert isinstance(inbound.message, FollowerState)
                got.append(inbound.message)
                assert inbound.received.hlc_stamp_s is not None  # Zenoh timestamping is on
                assert abs(inbound.received.hlc_stamp_s - time.time()) < 5.0
            for inbound in decoder.drain(statuses):
                assert isinstance(inbound.message, ProcessStatus)
                counters.update(inbound.message.counters)
            return bool(got) and counters.get("accepted", 0) >= 1

        wait_for(echo_and_counts_seen, 10, "echo of the valid state")
        assert got[0].index == 1 and got[0].r_m == (42.0, 2.0)
        assert got[0].header.sender_id == "echo-0"
        assert counters["drop_msgpack"] == 2 and counters["drop_non_finite"] == 1
        assert proc.poll() is None, "the receiver crashed on bad input"
        assert decoder.dropped_total == 0 and decoder.gaps["echo-0"] == 0

        os.kill(proc.pid, signal.SIGKILL)
        t0 = time.monotonic()
        wait_for(lambda: keys.alive("echo", 0) not in alive.poll(), 5, "token to vanish")
        print(f"token vanished {1000 * (time.monotonic() - t0):.1f} ms after SIGKILL")


@pytest.mark.timeout(60)
def test_peer_exits_cleanly_on_sigterm() -> None:
    swarm, port = f"term{os.getpid()}", free_port()
    keys = SwarmKeys(swarm)
    with echo_peer(swarm, loopback_endpoint(port)) as proc, \
            ZenohBus(ZenohConfig(connect=(loopback_endpoint(port),))) as bus:
        alive = bus.watch_alive(keys.all_alive())
        wait_for(lambda: bool(alive.poll()), 20, "echo liveliness token")
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
        wait_for(lambda: not alive.poll(), 5, "token withdrawn on clean exit")


@pytest.mark.timeout(60)
def test_arrival_stamps_come_from_the_receiving_thread_before_the_drain() -> None:
    """--latency-stamps: each sample is stamped as it reaches the process (a callback on
    Zenoh's own thread), so the stamp lies between the sender's put and our drain."""
    swarm, port = f"arr{os.getpid()}", free_port()
    keys = SwarmKeys(swarm)
    cfg = ZenohConfig(connect=(loopback_endpoint(port),), arrival_stamps=True)
    with echo_peer(swarm, loopback_endpoint(port)), ZenohBus(cfg) as bus:
        alive = bus.watch_alive(keys.all_alive())
        wait_until_alive(alive, {keys.alive("echo", 0)}, timeout_s=20)
        echoes = bus.subscribe(keys.follower_state(1))
        pub = bus.declare_publisher(keys.follower_state(0))
        wait_for(pub.matched, 10, "echo subscriber to match")
        stamper, got = Stamper("follower-0"), []

        def echoed() -> bool:
            pub.put(encode(state(stamper)))
            time.sleep(0.01)  # the drain comes well after the arrival, as a tick's does
            got.extend(echoes.drain())
            return len(got) >= 5

        wait_for(echoed, 20, "five echoes")
        for rx in got:
            assert rx.arrival_s is not None and rx.hlc_stamp_s is not None
            assert rx.hlc_stamp_s - 0.001 <= rx.arrival_s <= rx.recv_stamp_s
        # Stamped on arrival, not at the drain: echoes land during the 10-ms waits.
        assert max(rx.recv_stamp_s - rx.arrival_s for rx in got) > 0.001
