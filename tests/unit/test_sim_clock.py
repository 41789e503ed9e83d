"""The simulator's boot clock under a stall: caught up, not dropped; TIMESYNC and SYSTEM_TIME.

A fake clock drives `Simulator.run`: its sleep to a tick moves the clock there, and a
tick hook "stalls" the process by moving it further (what a SIGSTOP does to a real one).
"""

from __future__ import annotations

import itertools
import socket
from collections.abc import Iterator

import pytest

from agents.mavlink.wire import new_codec
from agents.scenario.model import HomeConfig, VehicleConfig
from sim_backend.runtime import SimConfig, Simulator, grid_spawn_ned
from sim_backend.setpoint import decode_setpoint
from tests.mavlink_fuzz import queued_datagrams

pytestmark = pytest.mark.realtime


class FakeClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def rig() -> Iterator[tuple[Simulator, FakeClock, socket.socket]]:
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    client.setblocking(False)
    clock = FakeClock()

    def sleep(seconds: float) -> None:
        clock.t += seconds

    sim = Simulator(grid_spawn_ned(3), VehicleConfig(), HomeConfig(),
                    SimConfig(listen_base_port=0, send_base_port=client.getsockname()[1]),
                    clock=clock, sleep=sleep)
    try:
        yield sim, clock, client
    finally:
        sim.close()
        client.close()


def stall_at(sim: Simulator, clock: FakeClock, tick: int, stall_s: float) -> None:
    def hook(t: float, _state: object) -> None:
        if round(t / sim.dt_s) == tick:
            clock.t += stall_s
    sim.on_tick.append(hook)


def test_a_stall_is_caught_up_in_sub_steps_without_a_telemetry_burst(rig) -> None:
    sim, clock, client = rig
    start = clock.t
    stall_at(sim, clock, 10, 0.5)
    stats = sim.run(lambda: False, max_ticks=40)
    assert sim.sim_time_s == pytest.approx(clock.t - start, abs=sim.dt_s + 1e-9)
    assert stats.catch_ups == 1 and stats.caught_up_ticks == 24 and stats.resyncs == 0
    assert stats.overruns == 1 and stats.ticks == 40
    grams = queued_datagrams(client)
    positions = [m for g in grams for m in g if m.get_type() == "LOCAL_POSITION_NED"]
    assert len(positions) == 40  # one per real tick, none for the 24 sub-steps
    assert len(grams) <= 40 + 2  # + this second's TIMESYNC request and SYSTEM_TIME
    boot_ms = [m.time_boot_ms for m in positions]
    steps = [b - a for a, b in itertools.pairwise(boot_ms)]
    assert sorted(set(steps)) == [20, 500]  # the boot clock kept the stall's time
    assert boot_ms[-1] == pytest.approx((clock.t - start) * 1000.0, abs=21)


def test_what_arrived_during_the_stall_is_stamped_after_it(rig) -> None:
    """A setpoint that waited out the stall must not trip the setpoint-loss failsafe."""
    sim, clock, _client = rig
    sp = decode_setpoint(3527, 1, (0.0,) * 3, (1.0, 0.0, 0.0), 0.0, 0.0, (0.0, 0.0, -5.0), 0.0)
    for ep in sim.endpoints:
        ep.autopilot.armed, ep.autopilot.mode = True, "OFFBOARD"
        ep.autopilot.on_setpoint(sp, 0.0, False)
    gcs = new_codec(255, 190)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def feed(t: float, _state: object) -> None:
        for sysid, port in enumerate(sim.listen_ports(), start=1):
            msg = gcs.set_position_target_local_ned_encode(0, sysid, 1, 1, 3527, 0, 0, 0, 1.0,
                                                           0, 0, 0, 0, 0, 0, 0)
            sender.sendto(msg.pack(gcs), ("127.0.0.1", port))
        if round(t / sim.dt_s) == 5:
            clock.t += 2.0  # stalled 2 s with the last setpoint queued
    sim.on_tick.append(feed)
    try:
        sim.run(lambda: False, max_ticks=20)
    finally:
        sender.close()
    for ep in sim.endpoints:
        assert ep.autopilot.failsafes == 0 and ep.autopilot.mode == "OFFBOARD"
    assert sim.stats.caught_up_ticks == 99


def test_a_stall_longer_than_the_catch_up_limit_drops_the_rest_and_counts_it(rig) -> None:
    sim, clock, _client = rig
    start = clock.t
    stall_at(sim, clock, 3, 100.0)
    stats = sim.run(lambda: False, max_ticks=10)
    assert stats.resyncs == 1
    assert sim.sim_time_s == pytest.approx(30.0 + 10 * sim.dt_s, abs=2 * sim.dt_s)
    assert clock.t - start > 100.0


def test_timesync_requests_are_answered_with_the_boot_clock_in_ns(rig) -> None:
    sim, clock, client = rig
    gcs = new_codec(255, 190)
    client.sendto(gcs.timesync_encode(0, 123456789).pack(gcs) +
                  gcs.system_time_encode(1_700_000_000_000_000, 5).pack(gcs),
                  ("127.0.0.1", sim.listen_ports()[0]))
    stall_at(sim, clock, 2, 0.3)
    sim.run(lambda: False, max_ticks=5)
    msgs = [m for g in queued_datagrams(client) for m in g
            if m.get_type() in ("TIMESYNC", "SYSTEM_TIME")]
    replies = [m for m in msgs if m.get_type() == "TIMESYNC" and m.tc1 != 0]
    assert [m.ts1 for m in replies] == [123456789]
    assert 0 <= replies[0].tc1 <= 2 * sim.dt_s * 1e9
    requests = [m for m in msgs if m.get_type() == "TIMESYNC" and m.tc1 == 0]
    assert len(requests) == 1 and [m.get_type() for m in msgs].count("SYSTEM_TIME") == 1
    assert sim.counters["system_time_ignored"] == 1 and sim.counters["timesync_answered"] == 1
    # Our reply to its request is matched and its round trip kept.
    client.sendto(gcs.timesync_encode(77, requests[0].ts1).pack(gcs),
                  ("127.0.0.1", sim.listen_ports()[0]))
    sim.run(lambda: False, max_ticks=1)
    assert sim.counters["timesync_replies"] == 1 and sim.clocks[0].last_rtt_s is not None


def test_a_paced_tick_sleeps_to_its_time_then_takes_what_arrived_without_waiting(rig) -> None:
    """One wake-up a tick: the sockets are read when the tick is due, never waited on."""
    sim, clock, client = rig
    gcs = new_codec(255, 190)
    client.sendto(gcs.timesync_encode(0, 5).pack(gcs), ("127.0.0.1", sim.listen_ports()[1]))
    waits: list[float | None] = []
    select = sim._selector.select

    def recorded(timeout: float | None = None) -> list:
        waits.append(timeout)
        return select(timeout)
    sim._selector.select = recorded  # type: ignore[method-assign]
    start = clock.t
    sim.run(lambda: False, max_ticks=3)
    assert waits and all(w == 0.0 for w in waits)
    assert clock.t - start == pytest.approx(3 * sim.dt_s)
    assert sim.counters["timesync_answered"] == 1
