"""Property tests: arbitrary field values in every handled message never make a handler raise.

A handler that raised would be contained by the endpoint's error boundary (outcome
"failed", counter handler_errors); these tests demand it never happens at all, that every
command is answered with exactly one COMMAND_ACK, and that the vehicles stay finite.
"""

from __future__ import annotations

import math
import socket
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from agents.mavlink.wire import new_codec
from agents.scenario.model import HomeConfig, VehicleConfig
from sim_backend.runtime import SimConfig, Simulator, grid_spawn_ned
from tests.mavlink_fuzz import (
    HANDLED_CLASSES,
    payload_size,
    queued_datagrams,
    raw_frame,
    target_offset,
)

pytestmark = pytest.mark.realtime

SETTINGS = settings(max_examples=150, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])
COMMANDS = (20, 21, 22, 176, 192, 400, 410, 510, 511, 512, 519, 520, 31000)
special = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, 1.0, -1.0, 21196.0, 6.0, 4.0,
                           1e30, -0.0, 2.0**31, 148.0, 24.0, 242.0, 0.5])
floats = st.one_of(special, st.floats(width=32))


@pytest.fixture(params=["px4", "ardupilot"])
def sim(request: pytest.FixtureRequest) -> Iterator[Simulator]:
    s = Simulator(grid_spawn_ned(1), VehicleConfig(), HomeConfig(),
                  SimConfig(listen_base_port=0, send_base_port=9, flavour=request.param))
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    client.setblocking(False)
    s.test_client = client  # type: ignore[attr-defined]
    try:
        yield s
    finally:
        client.close()
        s.close()


def deliver(sim: Simulator, data: bytes) -> list:
    client = sim.test_client  # type: ignore[attr-defined]
    queued_datagrams(client)  # drop telemetry streamed to us since the last example
    sim.endpoints[0].on_datagram(data, client.getsockname(), sim.sim_time_s, sim._rows[0])
    return [msg for datagram in queued_datagrams(client) for msg in datagram]


def check_healthy(sim: Simulator) -> None:
    sim.step_once()
    assert sim.counters["handler_errors"] == 0 and sim.counters["telemetry_errors"] == 0
    assert np.all(np.isfinite(sim.state.pos_ned_m)) and np.all(np.isfinite(sim.state.vel_ned_m_s))


@SETTINGS
@given(index=st.integers(0, len(HANDLED_CLASSES) - 1), payload=st.binary(max_size=255),
       target=st.sampled_from([0, 1, 7]))
def test_any_bytes_in_any_handled_message(sim: Simulator, index: int, payload: bytes,
                                          target: int) -> None:
    cls = HANDLED_CLASSES[index]
    # Put the target system where the message keeps it, so most examples reach the handler.
    data = bytearray(payload.ljust(payload_size(cls), b"\x00"))
    offset = target_offset(cls)
    if offset is not None:
        data[offset] = target
    deliver(sim, raw_frame(cls, bytes(data)))
    check_healthy(sim)


@SETTINGS
@given(command=st.one_of(st.sampled_from(COMMANDS), st.integers(0, 65535)),
       params=st.lists(floats, min_size=7, max_size=7), as_int=st.booleans(),
       xy=st.lists(st.one_of(st.just(2**31 - 1), st.integers(-2**31, 2**31 - 1)), min_size=2,
                   max_size=2), frame=st.integers(0, 255))
def test_commands_with_any_params_get_exactly_one_ack(sim: Simulator, command: int,
                                                      params: list[float], as_int: bool,
                                                      xy: list[int], frame: int) -> None:
    gcs = new_codec(255, 190)
    if as_int:
        msg = gcs.command_int_encode(1, 1, frame, command, 0, 0, *params[:4], xy[0], xy[1],
                                     params[6])
    else:
        msg = gcs.command_long_encode(1, 1, command, 0, *params)
    got = deliver(sim, msg.pack(gcs))
    acks = [m for m in got if m.get_type() == "COMMAND_ACK"]
    assert len(acks) == 1 and acks[0].command == command
    if acks[0].result != 0:
        assert any(m.get_type() == "STATUSTEXT" for m in got)
    check_healthy(sim)


@SETTINGS
@given(base=st.integers(0, 255), custom=st.one_of(
    st.integers(0, 2**32 - 1), st.sampled_from([4 | 8 << 24, 4 << 16 | 8 << 24, 4 << 16 | 9 << 24,
                                                21, 6 << 16, 4, 3, 4 << 16 | 4 << 24])))
def test_set_mode_any_custom_mode_is_acked_and_heartbeat_survives(sim: Simulator, base: int,
                                                                   custom: int) -> None:
    gcs = new_codec(255, 190)
    got = deliver(sim, gcs.set_mode_encode(1, base, custom).pack(gcs))
    assert got and got[0].get_type() == "COMMAND_ACK"
    ep = sim.endpoints[0]
    assert ep.build(0, sim._rows[0]) is not None  # the next HEARTBEAT can still be built
    check_healthy(sim)


@SETTINGS
@given(msg_id=st.sampled_from([24, 32, 0, 74]), interval=floats)
def test_any_set_interval_then_get_interval_answers(sim: Simulator, msg_id: int,
                                                    interval: float) -> None:
    # Found by the UDP fuzz: a huge interval set, then read back, overflowed int32.
    gcs = new_codec(255, 190)
    deliver(sim, gcs.command_long_encode(1, 1, 511, 0, msg_id, interval, 0, 0, 0, 0, 0).pack(gcs))
    got = deliver(sim, gcs.command_long_encode(1, 1, 510, 0, msg_id, 0, 0, 0, 0, 0, 0).pack(gcs))
    assert [m.get_type() for m in got if m.get_type() != "STATUSTEXT"][:2] == \
        ["COMMAND_ACK", "MESSAGE_INTERVAL"]
    check_healthy(sim)
