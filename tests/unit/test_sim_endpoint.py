"""Simulator stepped without sleeping: bad datagrams, commands, telemetry bundling."""

from __future__ import annotations

import math
import socket
from collections.abc import Iterator

import numpy as np
import pytest

from agents.mavlink.wire import new_codec
from agents.mavlink.wire_decode import decode_datagram
from agents.scenario.model import HomeConfig, VehicleConfig
from sim_backend.runtime import SimConfig, Simulator, grid_spawn_ned

pytestmark = pytest.mark.realtime


@pytest.fixture
def sim() -> Iterator[Simulator]:
    s = Simulator(grid_spawn_ned(2), VehicleConfig(), HomeConfig(),
                  SimConfig(listen_base_port=0, send_base_port=9))  # port 9: discard
    try:
        yield s
    finally:
        s.close()


def deliver(sim: Simulator, i: int, data: bytes) -> list:
    """Hand a datagram to vehicle i as if from a client socket; return what it answered."""
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    client.settimeout(0.2)
    try:
        sim.endpoints[i].on_datagram(data, client.getsockname(), sim.sim_time_s, sim._rows[i])
        try:
            reply, _ = client.recvfrom(65535)
        except TimeoutError:
            return []
        return list(decode_datagram(new_codec(250, 0), reply).messages)
    finally:
        client.close()


def test_garbage_other_sysid_and_nan_are_counted_not_fatal(sim: Simulator) -> None:
    gcs = new_codec(255, 190)
    assert deliver(sim, 0, b"\x00garbage\xfd\xfd\xfd") == []
    assert deliver(sim, 0, gcs.command_long_encode(2, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
                   .pack(gcs)[:-4]) == []
    assert deliver(sim, 0, gcs.command_long_encode(2, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
                   .pack(gcs)) == []
    nan_sp = gcs.set_position_target_local_ned_encode(0, 1, 1, 1, 3527, 0, 0, 0, math.nan, 0, 0,
                                                      0, 0, 0, 0, 0)
    assert deliver(sim, 0, nan_sp.pack(gcs)) == []
    for _ in range(3):
        sim.step_once()
    c = sim.counters
    assert c["bad_packets"] >= 2 and c["ignored_other_sysid"] == 1
    assert c["ignored_nonfinite"] == 1 and c["setpoints"] == 0
    ack = deliver(sim, 0, gcs.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(gcs))
    assert [(m.get_type(), m.command, m.result) for m in ack] == [("COMMAND_ACK", 400, 0)]
    assert ack[0].target_system == 255 and ack[0].target_component == 190


def test_request_message_interval_and_params(sim: Simulator) -> None:
    gcs = new_codec(255, 190)
    got = deliver(sim, 1, gcs.command_long_encode(2, 1, 512, 0, 148, 0, 0, 0, 0, 0, 0).pack(gcs))
    assert [m.get_type() for m in got] == ["COMMAND_ACK", "AUTOPILOT_VERSION"]
    assert got[1].get_srcSystem() == 2
    got = deliver(sim, 1, gcs.command_long_encode(2, 1, 511, 0, 32, 100000, 0, 0, 0, 0, 0)
                  .pack(gcs))
    assert got[0].result == 0 and sim.endpoints[1].intervals[32] == pytest.approx(0.1)
    got = deliver(sim, 1, gcs.command_long_encode(2, 1, 31000, 0, 0, 0, 0, 0, 0, 0, 0).pack(gcs))
    assert got[0].result == 3  # UNSUPPORTED
    got = deliver(sim, 1, gcs.param_request_read_encode(2, 1, b"MIS_TAKEOFF_ALT", -1).pack(gcs))
    assert got[0].get_type() == "PARAM_VALUE" and got[0].param_value == pytest.approx(2.5)
    got = deliver(sim, 1, gcs.param_set_encode(2, 1, b"MIS_TAKEOFF_ALT", 4.0, 9).pack(gcs))
    assert got[0].param_value == pytest.approx(4.0)
    assert sim.endpoints[1].autopilot.default_takeoff_alt_m == pytest.approx(4.0)
    got = deliver(sim, 1, gcs.param_request_list_encode(2, 1).pack(gcs))
    assert len(got) == len(sim.endpoints[1].params) and got[0].param_count == len(got)


def test_sim_time_advances_by_fixed_ticks_and_hooks_see_state(sim: Simulator) -> None:
    seen: list[float] = []
    sim.on_tick.append(lambda t, state: seen.append(t))
    for _ in range(10):
        sim.step_once()
    assert sim.sim_time_s == pytest.approx(10 * sim.dt_s) and seen[-1] == sim.sim_time_s
    snap = sim.snapshot()
    assert snap.pos_ned_m.shape == (2, 3) and snap.modes == ("HOLD", "HOLD")
    assert np.all(snap.pos_ned_m[:, 2] == 0.0)


def test_a_signed_vehicle_answers_a_request_with_frames_a_verifier_accepts(sim: Simulator) -> None:
    """The reply to REQUEST_MESSAGE follows its ACK on the wire: it must be packed after
    it too, or a verifying agent drops it as a replay (it did: the agents' first HEARTBEAT
    then waited for the 1 Hz stream, issue 15)."""
    from agents.mavlink.signing import SignatureVerifier
    from agents.mavlink.wire import frame_bytes, sign_outgoing

    key = bytes(range(1, 33))
    sim.endpoints[1].enforce_signing(key)
    gcs = new_codec(255, 190)
    sign_outgoing(gcs, key, 0, SignatureVerifier(key).now_ticks())
    verifier = SignatureVerifier(key, allowed_unsigned=frozenset())
    for wanted, name in ((0, "HEARTBEAT"), (148, "AUTOPILOT_VERSION")):
        got = deliver(sim, 1, gcs.command_long_encode(2, 1, 512, 0, wanted, 0, 0, 0, 0, 0, 0)
                      .pack(gcs))
        assert [m.get_type() for m in got] == ["COMMAND_ACK", name]
        assert [verifier.check(frame_bytes(m), m.get_msgId(), m.get_srcSystem(),
                               m.get_srcComponent()) for m in got] == [None, None]


def test_message_intervals_are_per_vehicle_and_slow_streams_keep_flowing(sim: Simulator) -> None:
    """A companion asks ATTITUDE and GLOBAL_POSITION_INT down to 4 Hz on its own vehicle
    (agents.mavlink.startup.set_rates): that vehicle streams them at 4 Hz to everyone
    listening, the other vehicle keeps its default, LOCAL_POSITION_NED stays at 50 Hz."""
    gcs = new_codec(255, 190)
    clients = []
    for i in range(2):
        client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        client.bind(("127.0.0.1", 0))
        client.setblocking(False)
        clients.append(client)
        sim.endpoints[i].on_datagram(gcs.heartbeat_encode(6, 8, 0, 0, 0).pack(gcs),
                                     client.getsockname(), sim.sim_time_s, sim._rows[i])
    try:
        for msg_id in (30, 33):
            sim.endpoints[0].on_datagram(
                gcs.command_long_encode(1, 1, 511, 0, msg_id, 250_000, 0, 0, 0, 0, 0).pack(gcs),
                clients[0].getsockname(), sim.sim_time_s, sim._rows[0])
        for _ in range(round(2.0 / sim.dt_s)):  # 2 s of ticks
            sim.step_once()
        counts = []
        for client in clients:
            seen: dict[str, int] = {}
            while True:
                try:
                    data = client.recv(65535)
                except BlockingIOError:
                    break
                for m in decode_datagram(new_codec(250, 0), data).messages:
                    seen[m.get_type()] = seen.get(m.get_type(), 0) + 1
            counts.append(seen)
    finally:
        for client in clients:
            client.close()
    slow, default = counts
    assert 7 <= slow["ATTITUDE"] <= 9 and 7 <= slow["GLOBAL_POSITION_INT"] <= 9
    assert slow["LOCAL_POSITION_NED"] >= 99 and default["ATTITUDE"] >= 99
    assert default["GLOBAL_POSITION_INT"] >= 99


def test_a_slower_loop_gets_its_position_at_its_own_rate(sim: Simulator) -> None:
    """A 20-Hz follower asks LOCAL_POSITION_NED down to its loop rate (agents.shell.vehicle_loop):
    on 50-Hz ticks the vehicle keeps the average rate (every 2.5 ticks), not 25 or 50 Hz."""
    gcs = new_codec(255, 190)
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    client.setblocking(False)
    try:
        sim.endpoints[0].on_datagram(
            gcs.command_long_encode(1, 1, 511, 0, 32, 50_000, 0, 0, 0, 0, 0).pack(gcs),
            client.getsockname(), sim.sim_time_s, sim._rows[0])
        for _ in range(round(2.0 / sim.dt_s)):  # 2 s of ticks
            sim.step_once()
        seen = 0
        while True:
            try:
                data = client.recv(65535)
            except BlockingIOError:
                break
            seen += sum(m.get_type() == "LOCAL_POSITION_NED"
                        for m in decode_datagram(new_codec(250, 0), data).messages)
    finally:
        client.close()
    assert 39 <= seen <= 41
