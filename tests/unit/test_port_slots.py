"""A port slot passed over when a process holds one of its ports anyway (the plugin's
fixtures: enclose.testing), and the error only when no slot is left."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from deploy.launch.port_slots import Held, port_slot, slot_ports
from deploy.launch.ports import ports_held
from errors import DeployError

pytestmark = pytest.mark.timeout(60)


def held_in(taken: set[int]) -> Held:
    """A probe that finds the ports of `taken` held (no socket: a unit test's)."""
    return lambda ports: [f"UDP {p}" for p in ports if p in taken]


def test_a_slot_with_a_port_held_is_passed_over(tmp_path: Path) -> None:
    first = slot_ports(0).start
    with port_slot(folder=tmp_path, slots=3, held=held_in({first + 3})) as slot:
        assert slot.index == 1
        # the lock of the slot passed over is not kept: a holder that does not probe gets it
        with port_slot(folder=tmp_path, slots=3) as other:
            assert other.index == 0


def test_no_free_slot_names_the_ports_held(tmp_path: Path) -> None:
    held = held_in({slot_ports(0).start, slot_ports(1).start + 5})
    named = r"no free port block: 15000-15249 \(UDP 15000 in use\); 15250-15499 \(UDP 15255"
    with pytest.raises(DeployError, match=named), port_slot(folder=tmp_path, slots=2,
                                                             held=held):
        pass


def test_slots_locked_by_others_are_waited_for_not_an_error(tmp_path: Path) -> None:
    def give_up() -> None:
        raise KeyboardInterrupt

    held = held_in(set(slot_ports(1)))
    # slot 0 locked by another holder, slot 1's ports held: wait for slot 0
    with port_slot(folder=tmp_path, slots=2), pytest.raises(KeyboardInterrupt), port_slot(
            give_up, folder=tmp_path, slots=2, held=held):
        pass


@pytest.mark.realtime
def test_ports_held_names_udp_and_listening_tcp_ports() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp, \
            socket.socket(socket.AF_INET, socket.SOCK_STREAM) as tcp:
        udp.bind(("127.0.0.1", 0))
        tcp.bind(("127.0.0.1", 0))
        tcp.listen()
        u, t = udp.getsockname()[1], tcp.getsockname()[1]
        assert ports_held(range(u, u + 1)) == [f"UDP {u}"]
        assert f"TCP {t}" in ports_held(range(t, t + 1), tcp=True)
        assert f"TCP {t}" not in ports_held(range(t, t + 1))
