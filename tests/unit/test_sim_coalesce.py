"""The simulator's receive loop naps between rounds (RX_COALESCE_S) while datagrams come
densely (the last tick brought more than one a nap) and its tick is far, never close to it
nor when they come sparsely, and still handles every datagram before the tick."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator
from types import SimpleNamespace

import pytest

from agents.mavlink.wire import encode, new_codec
from agents.scenario.model import HomeConfig, VehicleConfig
from sim_backend import runtime
from sim_backend.runtime import RX_COALESCE_S, SimConfig, Simulator, grid_spawn_ned

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(30)]


class FakeClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def rig(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Simulator, FakeClock, list[float],
                                                             socket.socket]]:
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    clock = FakeClock()
    naps: list[float] = []

    def nap(seconds: float) -> None:
        naps.append(seconds)
        clock.t += seconds

    monkeypatch.setattr(runtime, "time", SimpleNamespace(sleep=nap, time=time.time,
                                                         monotonic=time.monotonic))
    sim = Simulator(grid_spawn_ned(2), VehicleConfig(), HomeConfig(),
                    SimConfig(listen_base_port=0, send_base_port=client.getsockname()[1]),
                    clock=clock)
    try:
        yield sim, clock, naps, client
    finally:
        sim.close()
        client.close()


def send_heartbeats(sim: Simulator, client: socket.socket, count: int) -> None:
    gcs = new_codec(255, 190)
    port = sim.listen_ports()[0]
    for _ in range(count):
        client.sendto(encode(gcs, gcs.heartbeat_encode(6, 8, 0, 0, 4)), ("127.0.0.1", port))


def handled_when_queued(sim: Simulator, count: int) -> None:
    deadline = time.monotonic() + 5.0
    while sim.messages["HEARTBEAT:handled"] < count and time.monotonic() < deadline:
        sim.receive_until(-1.0)  # queued only: past deadlines never nap


def a_tick_with(sim: Simulator, client: socket.socket, datagrams: int) -> None:
    send_heartbeats(sim, client, datagrams)
    time.sleep(0.05)  # loopback delivery (the real sleep: the loop's is faked)
    handled_when_queued(sim, sim.messages["HEARTBEAT:handled"] + datagrams)
    sim.step_once()


def test_dense_datagrams_and_a_far_tick_nap_between_rounds_and_all_are_taken(rig) -> None:
    sim, clock, naps, client = rig
    a_tick_with(sim, client, round(sim.dt_s / RX_COALESCE_S))  # one a nap: dense
    before = sim.messages["HEARTBEAT:handled"]
    send_heartbeats(sim, client, 3)
    time.sleep(0.05)
    sim.receive_until(clock.t + 10 * RX_COALESCE_S)
    assert sim.messages["HEARTBEAT:handled"] == before + 3
    assert naps == [RX_COALESCE_S] * 3  # one round per datagram on one socket, a nap after each


def test_no_nap_when_the_tick_is_near(rig) -> None:
    sim, clock, naps, client = rig
    a_tick_with(sim, client, round(sim.dt_s / RX_COALESCE_S))
    before = sim.messages["HEARTBEAT:handled"]
    send_heartbeats(sim, client, 2)
    time.sleep(0.05)
    sim.receive_until(clock.t + 1.5 * RX_COALESCE_S)
    handled_when_queued(sim, before + 2)
    assert naps == []


def test_no_nap_when_datagrams_come_sparsely(rig) -> None:
    sim, clock, naps, client = rig
    a_tick_with(sim, client, 3)
    before = sim.messages["HEARTBEAT:handled"]
    send_heartbeats(sim, client, 3)
    time.sleep(0.05)
    sim.receive_until(clock.t + 10 * RX_COALESCE_S)
    assert sim.messages["HEARTBEAT:handled"] == before + 3
    assert naps == []
