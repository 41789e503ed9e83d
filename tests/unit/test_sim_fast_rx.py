"""A simulated vehicle's one-pass receive (agents.mavlink.fast_rx in sim_backend.endpoint)
pinned to the layered path it stands in for.

Two endpoints, one as it runs and one that takes every datagram through the gate's screen,
`decode_datagram` and `dispatch` alone, are handed the same datagrams: setpoints with every
kind of field (NaN, unknown frames, masks that fly nothing, other target systems), commands,
TIMESYNC, HEARTBEAT, a type the fast path leaves to the layered one and a type the dialect
lacks; good, forged, replayed, unsigned, MAVLink 1, mutated, truncated and spliced; under a
tight budget too.  Their counters, outcomes, autopilots, peers, gates, signature streams
and what they sent must stay equal.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2

from agents.mavlink.rx_gate import RxBudget
from agents.mavlink.signing import TICKS_PER_S, signing_timestamp
from agents.scenario.model import HomeConfig, VehicleConfig
from sim_backend import peers as peers_module
from sim_backend import telemetry as tm
from sim_backend.autopilot import Autopilot
from sim_backend.clock_services import ClockService
from sim_backend.endpoint import VehicleEndpoint
from sim_backend.params import ParamStore, default_params
from tests.mavlink_fuzz import damaged, signed_frame

pytestmark = pytest.mark.timeout(180)
KEY = bytes(range(1, 33))
OTHER_KEY = bytes(range(2, 34))
NOW_S = 1_800_000_000.0
NOW = signing_timestamp(NOW_S)
ADDRS = (("127.0.0.1", 14580), ("127.0.0.1", 14581), ("127.0.0.2", 14550))
SETPOINT = mavlink2.MAVLink_set_position_target_local_ned_message
# Setpoints most of all; then what an agent or a ground station sends, one type not in the
# fast path's table (PARAM_REQUEST_READ) and one the lean dialect lacks (MISSION_COUNT's
# neighbour, PARAM_EXT_REQUEST_READ 320).
CLASSES = (SETPOINT, SETPOINT, SETPOINT, SETPOINT, mavlink2.MAVLink_heartbeat_message,
           mavlink2.MAVLink_timesync_message, mavlink2.MAVLink_command_long_message,
           mavlink2.MAVLink_param_request_read_message,
           mavlink2.MAVLink_param_ext_request_read_message)
SETTINGS = settings(max_examples=250, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])
ROW = tm.Row(1000, (0.5, -1.0, -2.5), (0.1, 0.0, 0.0), 0.0, 0.0, 0.3, 0.0, False)


def setpoint_payload(draw: st.DrawFn) -> bytes:
    value = st.sampled_from((0.0, 1.5, -2.25, math.nan, math.inf)) | st.floats(width=32)
    mask = st.sampled_from((3527, 3576, 0, 4095, 2503)) | st.integers(0, 65535)
    payload = SETPOINT.unpacker.pack(
        draw(st.integers(0, 2**32 - 1)), *(draw(value) for _ in range(11)), draw(mask),
        draw(st.sampled_from((0, 1, 1, 2))), draw(st.sampled_from((0, 1))),
        draw(st.sampled_from((1, 1, 7, 8, 9, 3, 250))))
    return payload.rstrip(b"\0") or payload[:1] if draw(st.booleans()) else payload


@st.composite
def frames(draw: st.DrawFn) -> bytes:
    cls = draw(st.sampled_from(CLASSES))
    size = cls.unpacker.size
    if cls is SETPOINT and draw(st.integers(0, 3)):
        payload = setpoint_payload(draw)
    else:
        length = draw(st.sampled_from((size, size, max(1, size - 3), size + 2)))
        payload = draw(st.binary(min_size=length, max_size=length))
    sysid, compid = draw(st.sampled_from(((1, 1), (1, 1), (255, 190), (2, 1))))
    kind = draw(st.sampled_from(("good",) * 6 + ("unsigned", "v1", "wrong_key", "flags")))
    stamp = NOW + draw(st.sampled_from((1, 2, 3, 50, 0, -1, -61 * TICKS_PER_S,
                                        6 * TICKS_PER_S)))
    if kind == "v1":
        mav = mavlink2.MAVLink(None, sysid, compid)
        return bytes(mav.heartbeat_encode(6, 8, 0, 0, 4).pack(mav, force_mavlink1=True))
    frame = signed_frame(cls, payload, sysid, compid, None if kind == "unsigned" else stamp,
                  OTHER_KEY if kind == "wrong_key" else KEY, draw(st.sampled_from((0, 0, 1))),
                  2 if kind == "flags" else 0)
    if draw(st.integers(0, 7)) == 0:  # a flipped byte: CRC, header or signature
        at = draw(st.integers(0, len(frame) - 1))
        frame = frame[:at] + bytes((frame[at] ^ draw(st.integers(1, 255)),)) + frame[at + 1:]
    return frame


@st.composite
def datagrams(draw: st.DrawFn) -> tuple[bytes, tuple[str, int]]:
    data = damaged(draw, b"".join(draw(st.lists(frames(), min_size=1, max_size=4))))
    return data, draw(st.sampled_from(ADDRS))


class FakeSocket:
    """Records where each datagram went (its bytes carry the wall clock's signing stamps)."""

    def __init__(self) -> None:
        self.sent: list[tuple[int, tuple[str, int]]] = []

    def sendto(self, data: bytes, addr: tuple[str, int]) -> None:
        self.sent.append((data[0], addr))


class Layered(VehicleEndpoint):
    """The receive path without FastRx: the gate's screen, then `parse_datagram`."""

    def on_datagram(self, data: bytes, addr: tuple[str, int], now_s: float,
                    row: tm.Row) -> None:
        self.counters["rx_datagrams"] += 1
        admitted = self.gate.admit(data, addr, now_s)
        if admitted:
            self.parse_datagram(admitted, addr, now_s, row)


def endpoint(cls: type[VehicleEndpoint], key: bytes | None,
             budget: RxBudget | None) -> VehicleEndpoint:
    home, counters = HomeConfig(), Counter[str]()
    ep = cls(1, FakeSocket(), ("127.0.0.1", 14580),  # type: ignore[arg-type]
             Autopilot("px4", home.alt_m), ParamStore("px4", default_params("px4", 1,
                                                                         VehicleConfig())),
             home, 50.0, counters)
    ClockService(ep.mav, ep.send_to, lambda: 12.5, lambda: NOW_S, counters).attach(ep)
    if key is not None:
        ep.enforce_signing(key)
        assert ep.verifier is not None
        ep.verifier.clock = lambda: NOW_S
    if budget is not None:
        ep.gate.budget = budget
    return ep


def snapshot(ep: VehicleEndpoint) -> dict[str, Any]:
    v, ap = ep.verifier, ep.autopilot
    assert isinstance(ep.sock, FakeSocket)
    return {
        "counters": +ep.counters, "messages": +ep.messages, "peers": ep.peers,
        "autopilot": repr(sorted(vars(ap).items())), "sent": ep.sock.sent,
        "intervals": ep.intervals, "gate": (ep.gate.datagrams, ep.gate.parsed_bytes,
                                            ep.gate.carried),
        "verifier": None if v is None else (+v.counters, list(v.streams.items()), v.latest,
                                            v.evicted_floor),
    }


@SETTINGS
@given(st.lists(st.lists(datagrams(), max_size=5), min_size=1, max_size=4),
       st.sampled_from((KEY, KEY, None)),
       st.sampled_from((None, None, RxBudget(2, 200), RxBudget(8, 120))),
       st.sampled_from((peers_module.MAX_PEERS, 2)))
def test_fast_path_keeps_every_verdict_outcome_and_state(
        ticks: list[list[tuple[bytes, tuple[str, int]]]], key: bytes | None,
        budget: RxBudget | None, max_peers: int) -> None:
    """A peer table of 2 fills with our 3 senders: a newcomer is then refused (signed) or
    evicts the stalest (unsigned), once per datagram on either path."""
    fast, layered = endpoint(VehicleEndpoint, key, budget), endpoint(Layered, key, budget)
    saved, peers_module.MAX_PEERS = peers_module.MAX_PEERS, max_peers
    try:
        for t, datagrams_of_tick in enumerate(ticks):
            for ep in (fast, layered):
                ep.gate.new_tick()
                for data, addr in datagrams_of_tick:
                    if ep.gate.open:
                        ep.on_datagram(data, addr, 10.0 + 0.02 * t, ROW)
            assert snapshot(fast) == snapshot(layered)
    finally:
        peers_module.MAX_PEERS = saved


def test_a_signed_setpoint_is_flown_from_its_fields_with_one_hash(
        monkeypatch: pytest.MonkeyPatch) -> None:
    ep = endpoint(VehicleEndpoint, KEY, None)
    assert ep.verifier is not None
    payload = SETPOINT.unpacker.pack(0, 0.0, 0.0, 0.0, 1.5, -0.5, 0.25, 0.0, 0.0, 0.0, 0.0,
                                     0.0, 3527, 1, 1, 1)
    data = signed_frame(SETPOINT, payload, 1, 1, NOW + 5, KEY)

    def layered(*_: object) -> None:
        raise AssertionError("the layered path's screen or check ran")

    # The layered path hashes a frame twice: the gate's screen, then the check per message.
    monkeypatch.setattr(ep.verifier, "screen", layered)
    monkeypatch.setattr(ep.verifier, "check", layered)
    ep.on_datagram(data, ADDRS[0], 10.0, ROW)
    assert ep.messages == Counter({"SET_POSITION_TARGET_LOCAL_NED:handled": 1})
    assert ep.autopilot._setpoint is not None
    assert ep.autopilot._setpoint.vel_ned_m_s == (1.5, -0.5, 0.25)
    assert ep.peers == {ADDRS[0]: 10.0}
    assert ep.verifier.counters["accepted_signed"] == 1
    ep.on_datagram(data, ADDRS[0], 10.02, ROW)  # the same frame again: a replay
    assert ep.counters["signing_rejected_replay"] == 1
    assert ep.messages["SET_POSITION_TARGET_LOCAL_NED:handled"] == 1


def test_a_sender_refused_a_peer_slot_is_counted_once_per_datagram() -> None:
    """A datagram the fast path takes in part (a setpoint, then a type it leaves to the
    layered path) remembers its sender once, as the layered path does."""
    setpoint = SETPOINT.unpacker.pack(0, *([0.0] * 11), 3527, 1, 1, 1)
    request = mavlink2.MAVLink_param_request_read_message.unpacker.pack(-1, 1, 1, b"SYSID")
    saved, peers_module.MAX_PEERS = peers_module.MAX_PEERS, 2
    try:
        for cls in (VehicleEndpoint, Layered):
            ep = endpoint(cls, KEY, None)
            for k, addr in enumerate(ADDRS):
                stamp = NOW + 10 * k
                ep.on_datagram(signed_frame(SETPOINT, setpoint, 1, 1, stamp, KEY)
                               + signed_frame(mavlink2.MAVLink_param_request_read_message,
                                              request, 1, 1, stamp + 1, KEY), addr, 10.0, ROW)
            assert ep.counters["peers_refused"] == 1, cls
            assert set(ep.peers) == set(ADDRS[:2])
    finally:
        peers_module.MAX_PEERS = saved
