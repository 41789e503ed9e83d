"""Bounded work under flood: a poll reads at most its budget, a vehicle's peer table is
not the flooder's to fill, one vehicle's flooded port costs the simulator one budget."""

from __future__ import annotations

import socket
import time
from collections import Counter
from collections.abc import Iterator

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.mavlink.adapter import AdapterConfig, MavlinkAdapter
from agents.mavlink.rx_gate import ADAPTER_BUDGET, VEHICLE_BUDGET, RxBudget, RxGate
from agents.mavlink.signing import SignatureVerifier, signing_timestamp
from agents.mavlink.signing_keys import vehicle_key
from agents.mavlink.wire import encode, new_codec, sign_outgoing
from agents.scenario.model import HomeConfig, VehicleConfig
from errors import ConfigError, SimulatorError
from sim_backend.peers import MAX_PEERS
from sim_backend.runtime import SimConfig, Simulator, grid_spawn_ned
from sim_backend.sim_values import parse_peer_hosts

SECRET = bytes(range(7, 39))


class StuffedSocket:
    """A socket whose receive buffer holds `datagrams`: counts the reads a poll makes."""

    def __init__(self, datagrams: list[bytes]) -> None:
        self.queue = list(datagrams)
        self.reads = 0

    def recvmsg(self, _size: int, _anc: int) -> tuple[bytes, list, int, tuple[str, int]]:
        if not self.queue:
            raise BlockingIOError
        self.reads += 1
        return self.queue.pop(0), [], 0, ("127.0.0.1", 4000)

    def close(self) -> None:
        pass


def signed_position(key: bytes, x: float = 1.0, pad_to: int = 0, mav=None) -> bytes:  # type: ignore[no-untyped-def]
    if mav is None:
        mav = new_codec(1, 1)
        sign_outgoing(mav, key, 0, signing_timestamp(time.time()))
    frames = encode(mav, mav.local_position_ned_encode(10, x, 2.0, -3.0, 0, 0, 0))
    while len(frames) < pad_to:  # more frames of the stream: a long, well-signed datagram
        frames += encode(mav, mav.local_position_ned_encode(10, x, 2.0, -3.0, 0, 0, 0))
    return frames


def stuffed_adapter(datagrams: list[bytes]) -> tuple[MavlinkAdapter, StuffedSocket]:
    ad = MavlinkAdapter(AdapterConfig(local_port=0, target_sysid=1,
                                      signing_key=vehicle_key(SECRET, 1)))
    sock = StuffedSocket(datagrams)
    ad.sock = sock  # type: ignore[assignment]
    return ad, sock


def test_a_poll_reads_at_most_its_budget_of_a_stuffed_socket() -> None:
    forged = signed_position(vehicle_key(SECRET, 2))  # signed, by another vehicle's key
    ad, sock = stuffed_adapter([forged] * 499 + [signed_position(vehicle_key(SECRET, 1))])
    ad.poll()
    assert sock.reads == ADAPTER_BUDGET.datagrams
    assert ad.counters["signing_rejected_bad_signature"] == ADAPTER_BUDGET.datagrams
    assert not ad.telemetry_seen
    ad.poll()
    assert sock.reads == 500 and ad.telemetry_seen  # the real frame waited, it was not lost
    assert ad.state.pos_enu_m == pytest.approx((2.0, 1.0, 3.0))


def test_a_poll_parses_at_most_its_byte_budget_and_keeps_the_rest() -> None:
    key = vehicle_key(SECRET, 1)
    vehicle = new_codec(1, 1)  # one stream: each datagram stamped after the one before
    sign_outgoing(vehicle, key, 0, signing_timestamp(time.time()))
    bigs = [signed_position(key, x=float(k), pad_to=6000, mav=vehicle) for k in range(10)]
    ad, sock = stuffed_adapter(bigs)
    ad.poll()
    per_poll = ADAPTER_BUDGET.parse_bytes // len(bigs[0])  # whole datagrams that fit
    assert sock.reads == per_poll + 1  # the one that did not fit waits for the next poll
    assert ad.state.pos_enu_m[1] == pytest.approx(per_poll - 1)
    for _ in range(10):
        ad.poll()
    assert sock.reads == 10 and ad.state.pos_enu_m[1] == pytest.approx(9.0)
    assert ad.counters["mav_flood_drops"] == 0 and ad.counters["signing_rejected_replay"] == 0
    # "rx_<x>" in a follower's status is link x's count (deploy.recording.links): not ours.
    assert not [k for k in ad.counters if k.startswith("rx_")]


def test_a_datagram_larger_than_a_whole_budget_is_cut() -> None:
    key = vehicle_key(SECRET, 1)
    huge = signed_position(key, pad_to=ADAPTER_BUDGET.parse_bytes + 5000)
    ad, _sock = stuffed_adapter([huge])
    ad.poll()
    assert ad.telemetry_seen and ad.counters["mav_flood_drops"] == 1
    assert ad.counters["mav_flood_bytes"] == len(huge) - ADAPTER_BUDGET.parse_bytes


def test_gate_screens_first_and_keeps_what_does_not_fit() -> None:
    counters: Counter[str] = Counter()
    key = vehicle_key(SECRET, 1)
    gate = RxGate("t", RxBudget(datagrams=3, parse_bytes=100), counters,
                  SignatureVerifier(key, allowed_unsigned=frozenset()))
    good = signed_position(key)
    assert gate.admit(b"\x00" * 64, None) is None
    assert gate.admit(good, None) == good and gate.open
    assert gate.admit(good * 2, ("127.0.0.1", 5), 7.0) is None and not gate.open
    assert counters["signing_rejected_malformed"] == 1 and counters["mav_flood_drops"] == 0
    assert gate.new_tick() == (good * 2, ("127.0.0.1", 5), 7.0)
    assert gate.parsed_bytes == 2 * len(good) and gate.open
    assert gate.new_tick() is None and gate.parsed_bytes == 0


@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=400))
def test_screen_takes_any_bytes(data: bytes) -> None:
    v = SignatureVerifier(vehicle_key(SECRET, 1), key_of_vehicle=lambda s: vehicle_key(SECRET, s))
    for datagram in (data, b"\xfd" + data, b"\xfe" + data, b"\xfd" + bytes([len(data)]) + data):
        v.screen(datagram)
    assert v.streams == {}


# ---- the simulated vehicle's side --------------------------------------------------------
def make_sim(**signing: bytes) -> Simulator:
    return Simulator(grid_spawn_ned(2), VehicleConfig(), HomeConfig(),
                     SimConfig(listen_base_port=0, send_base_port=9, **signing))


@pytest.fixture
def signed_sim() -> Iterator[Simulator]:
    s = make_sim(signing_secret=SECRET)
    try:
        yield s
    finally:
        s.close()


def heartbeat(mav) -> bytes:  # type: ignore[no-untyped-def]
    return encode(mav, mav.heartbeat_encode(6, 8, 0, 0, 4))


def gcs(key: bytes | None, link_id: int = 0):  # type: ignore[no-untyped-def]
    mav = new_codec(255, 190)
    if key is not None:
        sign_outgoing(mav, key, link_id, signing_timestamp(time.time()))
    return mav


@pytest.mark.realtime
def test_unsigned_heartbeat_registers_no_peer_when_signing(signed_sim: Simulator) -> None:
    ep, row = signed_sim.endpoints[0], signed_sim._rows[0]
    ep.on_datagram(heartbeat(gcs(None)), ("127.0.0.1", 5000), 0.0, row)
    assert signed_sim.messages["HEARTBEAT:handled"] == 1  # accepted, as PX4 does ...
    assert ep.peers == {}  # ... but it buys no telemetry
    ep.on_datagram(heartbeat(gcs(vehicle_key(SECRET, 1))), ("127.0.0.1", 5001), 0.0, row)
    assert list(ep.peers) == [("127.0.0.1", 5001)]


@pytest.mark.realtime
def test_spoofed_frames_do_not_churn_the_peer_table(signed_sim: Simulator) -> None:
    ep, row = signed_sim.endpoints[0], signed_sim._rows[0]
    real = [("127.0.0.1", 6000 + k) for k in range(MAX_PEERS)]
    for addr in real:
        ep.on_datagram(heartbeat(gcs(vehicle_key(SECRET, 1))), addr, 1.0, row)
    other = gcs(vehicle_key(SECRET, 2), link_id=1)  # vehicle 2's agent, on its own link
    for k in range(100):
        ep.on_datagram(heartbeat(other), ("127.0.0.1", 7000 + k), 2.0, row)
        ep.on_datagram(heartbeat(gcs(None)), ("127.0.0.1", 8000 + k), 2.0, row)
    assert sorted(ep.peers) == real
    assert signed_sim.counters["signing_rejected_wrong_key"] == 100
    assert signed_sim.counters["signing_wrong_key_vehicle_2"] == 100
    # A newcomer with the right key does not evict a live peer either; a silent one it does.
    ep.on_datagram(heartbeat(gcs(vehicle_key(SECRET, 1))), ("127.0.0.1", 9000), 3.0, row)
    assert ("127.0.0.1", 9000) not in ep.peers and signed_sim.counters["peers_refused"] == 1
    ep.on_datagram(heartbeat(gcs(vehicle_key(SECRET, 1))), ("127.0.0.1", 9000), 40.0, row)
    assert ("127.0.0.1", 9000) in ep.peers and len(ep.peers) == MAX_PEERS


@pytest.mark.realtime
def test_without_signing_any_sender_is_a_peer_as_before() -> None:
    sim = make_sim()
    try:
        ep, row = sim.endpoints[0], sim._rows[0]
        for k in range(MAX_PEERS + 1):
            ep.on_datagram(heartbeat(gcs(None)), ("127.0.0.1", 6000 + k), float(k), row)
        assert len(ep.peers) == MAX_PEERS and ("127.0.0.1", 6000) not in ep.peers
    finally:
        sim.close()


@pytest.mark.realtime
def test_a_flooded_vehicle_costs_one_budget_a_tick_and_the_others_are_served(
        signed_sim: Simulator) -> None:
    ports = signed_sim.listen_ports()
    flood = heartbeat(gcs(vehicle_key(SECRET, 2), link_id=1))  # wrong key for vehicle 1
    good = gcs(vehicle_key(SECRET, 2), link_id=1)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        tx.bind(("127.0.0.1", 0))
        for _ in range(2 * VEHICLE_BUDGET.datagrams):
            tx.sendto(flood, ("127.0.0.1", ports[0]))
        arm = good.command_long_encode(2, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        tx.sendto(encode(good, arm), ("127.0.0.1", ports[1]))
        # Serve until a deadline, as a paced tick does: vehicle 1's socket rests once its
        # budget is spent (no busy loop on it), vehicle 2's command is handled.
        signed_sim.receive_until(time.monotonic() + 0.3)
        c = signed_sim.counters
        assert c["signing_rejected_wrong_key"] == VEHICLE_BUDGET.datagrams
        assert c["mav_budget_spent"] >= 1 and c["commands"] == 1
        signed_sim.step_once()  # the tick ends; the next one's budget takes the rest
        signed_sim.receive_until(time.monotonic() + 0.3)
        assert c["signing_rejected_wrong_key"] == 2 * VEHICLE_BUDGET.datagrams


def test_an_unsigned_heartbeat_prefix_vouches_for_itself_alone() -> None:
    """8 or 12 bytes claiming HEARTBEAT (no CRC checked by the screen) in front of a
    datagram of garbage: the gate hands the parser that one frame, not the kilobytes."""
    counters: Counter[str] = Counter()
    gate = RxGate("t", VEHICLE_BUDGET, counters, SignatureVerifier(vehicle_key(SECRET, 1)))
    v2 = b"\xfd\x00\x00\x00\x01\x01\x00\x00\x00" + b"\x00" * 3  # 12 bytes, id 0, no payload
    v1 = b"\xfe\x00\x00\x01\x01\x00" + b"\x00" * 2  # 8 bytes, id 0
    for prefix in (v2, v1):
        assert gate.admit(prefix + b"\xfd\x01" * 4000, None) == prefix
    real = heartbeat(gcs(None))
    assert gate.admit(real, None) == real  # a whole unsigned HEARTBEAT passes as before
    signed = signed_position(vehicle_key(SECRET, 1), pad_to=300)
    assert gate.admit(signed, None) == signed  # signed datagrams are not cut
    assert counters["unsigned_tails"] == 2


def connected_sim(peer: str, host: str = "0.0.0.0") -> Simulator:
    return Simulator(grid_spawn_ned(1), VehicleConfig(), HomeConfig(),
                     SimConfig(host=host, listen_base_port=0, send_base_port=14940,
                               peer_hosts=(peer,)))


@pytest.mark.realtime
def test_a_vehicle_that_knows_its_agent_hears_no_one_else() -> None:
    sim = connected_sim("127.0.0.1")
    port = sim.listen_ports()[0]
    agent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        agent.bind(("127.0.0.1", 14940))
        other.bind(("127.0.0.2", 0))  # another address (all of 127/8 is loopback)
        for _ in range(50):
            other.sendto(b"\xfd\x00" + b"\x00" * 40, ("127.0.0.1", port))
        agent.sendto(heartbeat(gcs(None)), ("127.0.0.1", port))
        deadline = time.monotonic() + 2.0
        while sim.messages["HEARTBEAT:handled"] == 0 and time.monotonic() < deadline:
            sim.receive_until(time.monotonic() + 0.05)
        assert sim.messages["HEARTBEAT:handled"] == 1
        assert sim.counters["rx_datagrams"] == 1  # the kernel dropped the 50 unread
        assert sim.endpoints[0].default_dest == ("127.0.0.1", 14940)
    finally:
        agent.close()
        other.close()
        sim.close()


@pytest.mark.realtime
def test_a_wildcard_vehicle_sends_each_datagram_to_a_local_agent_once() -> None:
    """Bound to 0.0.0.0 with no peer known: the default destination is the loopback, the
    address a local agent sends from, so the two are one (issue 50: every frame twice)."""
    sim = Simulator(grid_spawn_ned(1), VehicleConfig(), HomeConfig(),
                    SimConfig(host="0.0.0.0", listen_base_port=0, send_base_port=14941))
    agent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        agent.bind(("127.0.0.1", 14941))
        agent.sendto(heartbeat(gcs(None)), ("127.0.0.1", sim.listen_ports()[0]))
        deadline = time.monotonic() + 2.0
        while not sim.endpoints[0].peers and time.monotonic() < deadline:
            sim.receive_until(time.monotonic() + 0.05)
        before = sim.counters["tx_datagrams"]
        sim.endpoints[0].broadcast(b"x", 0.0)
        assert sim.counters["tx_datagrams"] - before == 1
    finally:
        agent.close()
        sim.close()


def test_peer_addresses_are_one_per_vehicle() -> None:
    with pytest.raises(SimulatorError, match="peer_hosts"):
        Simulator(grid_spawn_ned(2), VehicleConfig(), HomeConfig(),
                  SimConfig(listen_base_port=0, peer_hosts=("127.0.0.1",)))


def test_peer_addresses_are_parsed_and_a_bad_one_named() -> None:
    assert parse_peer_hosts(None) == () and parse_peer_hosts("") == ()
    assert parse_peer_hosts("127.0.0.1, 10.77.0.2") == ("127.0.0.1", "10.77.0.2")
    with pytest.raises(ConfigError, match=r"mav_peers.*'ground'"):
        parse_peer_hosts("127.0.0.1,ground")
