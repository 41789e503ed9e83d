"""The MAVLink port blocks of a run: vehicles and agents never share a port, at any size."""

from __future__ import annotations

import socket

import pytest

from deploy.launch.ports import PX4_SITL_BASES, mavlink_bases, udp_block_free

pytestmark = pytest.mark.realtime


@pytest.mark.timeout(60)
@pytest.mark.parametrize("count", [6, 34, 40, 66, 130])
def test_vehicle_and_agent_blocks_never_overlap(count: int) -> None:
    vehicle, agent = mavlink_bases(count)
    assert set(range(vehicle, vehicle + count)).isdisjoint(range(agent, agent + count))
    if count <= abs(PX4_SITL_BASES[0] - PX4_SITL_BASES[1]) and udp_block_free(
            PX4_SITL_BASES[0], count) and udp_block_free(PX4_SITL_BASES[1], count):
        assert (vehicle, agent) == PX4_SITL_BASES  # PX4 SITL's ports while they fit


@pytest.mark.timeout(60)
def test_a_held_port_moves_the_blocks_elsewhere() -> None:
    vehicle, _agent = mavlink_bases(4)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as held:
        held.bind(("127.0.0.1", vehicle + 2))
        moved, agent = mavlink_bases(4)
    assert not moved <= vehicle + 2 < moved + 4
    assert set(range(moved, moved + 4)).isdisjoint(range(agent, agent + 4))
