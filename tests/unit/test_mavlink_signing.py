"""MAVLink 2 signing: the verifier checks the signature before it trusts a timestamp."""

from __future__ import annotations

import socket
import stat
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.mavlink.signing import TICKS_PER_S, SignatureVerifier, signing_timestamp
from agents.mavlink.signing_keys import key_from_passphrase, load_key, write_key
from agents.mavlink.wire import new_codec, sign_outgoing
from agents.scenario.model import HomeConfig, VehicleConfig
from errors import ConfigError
from sim_backend.runtime import SimConfig, Simulator, grid_spawn_ned

KEY = bytes(range(1, 33))
NOW_S = 1_800_000_000.0
ARM_DISARM, NAV_LAND = 400, 21


def signer(key: bytes = KEY, stamp_s: float = NOW_S, link_id: int = 0, sysid: int = 245):
    mav = new_codec(sysid, 191)
    sign_outgoing(mav, key, link_id, signing_timestamp(stamp_s))
    return mav


def disarm(mav) -> bytes:  # type: ignore[no-untyped-def]
    data: bytes = mav.command_long_encode(1, 1, ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0).pack(mav)
    return data


def verdict(v: SignatureVerifier, frame: bytes, msg_id: int = 76) -> str | None:
    return v.check(frame, msg_id, frame[5], frame[6])


def test_key_file_is_private_and_checked(tmp_path: Path) -> None:
    key = write_key(tmp_path / "k.bin")
    assert load_key(tmp_path / "k.bin") == key and len(key) == 32
    assert stat.S_IMODE((tmp_path / "k.bin").stat().st_mode) == 0o600
    (tmp_path / "short").write_bytes(b"x" * 31)
    (tmp_path / "zero").write_bytes(bytes(32))
    for bad in ("short", "zero", "missing"):
        with pytest.raises(ConfigError, match="signing_key"):
            load_key(tmp_path / bad)
    assert key_from_passphrase("secret") == __import__("hashlib").sha256(b"secret").digest()


def test_good_unsigned_wrong_key_and_replay() -> None:
    v = SignatureVerifier(KEY, clock=lambda: NOW_S)
    good = disarm(signer())
    assert verdict(v, good) is None
    assert verdict(v, good) == "replay"  # byte-exact replay
    assert verdict(v, disarm(new_codec(245, 191))) == "unsigned"
    assert verdict(v, disarm(signer(key=bytes(range(2, 34))))) == "bad_signature"
    hb_codec = new_codec(255, 190)
    heartbeat = hb_codec.heartbeat_encode(6, 8, 0, 0, 4).pack(hb_codec)
    assert verdict(v, heartbeat, msg_id=0) is None  # PX4 accepts HEARTBEAT unsigned
    assert v.counters["rejected_replay"] == 1 and v.counters["accepted_signed"] == 1


def test_a_screened_frame_is_hashed_once_and_a_forgery_of_it_still_refused(
        monkeypatch: pytest.MonkeyPatch) -> None:
    import agents.mavlink.signing as signing

    hashed: list[bytes] = []
    real = signing.signature

    def counting(key: bytes, part: bytes) -> bytes:
        hashed.append(part)
        return real(key, part)

    monkeypatch.setattr(signing, "signature", counting)
    v = SignatureVerifier(KEY, clock=lambda: NOW_S)
    good = disarm(signer())
    assert v.screen(good) is None and verdict(v, good) is None
    assert len(hashed) == 1  # screen hashed it; check of the same bytes did not
    assert verdict(v, good) == "replay" and len(hashed) == 2  # the memo is spent
    second = disarm(signer(stamp_s=NOW_S + 1.0))
    forged = second[:-6] + bytes(6)
    assert v.screen(second) is None
    assert verdict(v, forged) == "bad_signature"  # same signed part, another signature
    assert verdict(v, second) is None


def test_new_stream_more_than_a_minute_behind_is_refused() -> None:
    v = SignatureVerifier(KEY, clock=lambda: NOW_S)
    assert verdict(v, disarm(signer(stamp_s=NOW_S - 61.0, link_id=1))) == "replay"
    assert verdict(v, disarm(signer(stamp_s=NOW_S - 59.0, link_id=2))) is None


def test_forged_future_timestamp_does_not_lock_the_sender_out() -> None:
    """The attack on pymavlink 2.4.50: a badly signed packet stamped far ahead, on the
    sender's stream, moves pymavlink's stream timestamp and locks the sender out; ours not."""
    legit = signer()
    forger = signer(key=bytes(32 * [7]), stamp_s=NOW_S + 3600.0)  # right stream, wrong key
    forged = disarm(forger)
    ours = SignatureVerifier(KEY, clock=lambda: NOW_S)
    assert verdict(ours, forged) == "bad_signature"
    assert verdict(ours, disarm(legit)) is None  # the real sender still gets through
    assert verdict(ours, disarm(legit)) is None
    # pymavlink's own check (what we do not rely on) is locked out by the same packet:
    theirs = new_codec(1, 1)
    theirs.signing.secret_key = KEY
    theirs.signing.timestamp = signing_timestamp(NOW_S)
    assert not theirs.check_signature(bytearray(forged), 245, 191)
    assert not theirs.check_signature(bytearray(disarm(legit)), 245, 191)


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_every_single_byte_mutation_of_a_signed_command_is_refused(data: st.DataObject) -> None:
    frame = bytearray(disarm(signer()))
    pos = data.draw(st.integers(0, len(frame) - 1))
    frame[pos] ^= data.draw(st.integers(1, 255))
    v = SignatureVerifier(KEY, clock=lambda: NOW_S)
    assert verdict(v, bytes(frame)) is not None


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300), st.integers(0, 2**24 - 1))
def test_random_frames_never_pass_for_a_command(frame: bytes, msg_id: int) -> None:
    v = SignatureVerifier(KEY, clock=lambda: NOW_S, allowed_unsigned=frozenset())
    assert v.check(frame, msg_id, 1, 1) is not None


@pytest.fixture
def signed_sim() -> Iterator[Simulator]:
    s = Simulator(grid_spawn_ned(1), VehicleConfig(), HomeConfig(),
                  SimConfig(listen_base_port=0, send_base_port=9, signing_key=KEY))
    try:
        yield s
    finally:
        s.close()


@pytest.mark.realtime
def test_vehicle_with_a_key_drops_unsigned_commands_and_obeys_signed_ones(
        signed_sim: Simulator) -> None:
    ep = signed_sim.endpoints[0]
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    try:
        addr = client.getsockname()
        row = signed_sim._rows[0]
        ep.on_datagram(disarm(new_codec(250, 190)), addr, 0.0, row)
        land = new_codec(250, 190)
        ep.on_datagram(land.command_long_encode(1, 1, NAV_LAND, 0, *[0] * 7).pack(land),
                       addr, 0.0, row)
        assert signed_sim.counters["signing_rejected_unsigned"] == 2
        assert signed_sim.counters["commands"] == 0 and addr not in ep.peers
        mav = new_codec(245, 191)
        sign_outgoing(mav, KEY, 0, signing_timestamp(__import__("time").time()))
        ep.on_datagram(disarm(mav), addr, 0.0, row)
        assert signed_sim.counters["commands"] == 1 and addr in ep.peers
    finally:
        client.close()


def test_timestamp_units() -> None:
    assert signing_timestamp(1420070400.0 + 1.0) == TICKS_PER_S


def test_fast_path_signs_as_pymavlink_does() -> None:
    """The simulator's hand-packed position messages carry the same signature block."""
    from pymavlink.dialects.v20 import common as mavlink2

    from agents.mavlink.wire import encode, encode_fields
    a, b = signer(sysid=1), signer(sysid=1)
    fields = (1234, 1.0, -2.0, -3.5, 0.25, 0.0, -0.5)
    cls = mavlink2.MAVLink_local_position_ned_message
    fast = encode_fields(b, cls, *fields)
    assert fast == encode(a, cls(*fields))
    assert verdict(SignatureVerifier(KEY, clock=lambda: NOW_S), fast, cls.id) is None


def test_signing_stream_keeps_to_the_wall_clock() -> None:
    """pymavlink adds 1 tick per packet; a stream keyed an hour ago must still be taken as
    a fresh stream by a receiver that (re)starts now."""
    import time

    from agents.mavlink.wire import encode
    now = time.time()
    mav = signer(stamp_s=now - 3600.0)
    frame = encode(mav, mav.command_long_encode(1, 1, ARM_DISARM, 0, 0, 0, 0, 0, 0, 0, 0))
    assert int.from_bytes(frame[-12:-6], "little") >= signing_timestamp(now)
    assert SignatureVerifier(KEY).check(frame, 76, 245, 191) is None


@pytest.mark.realtime
def test_keyed_adapter_takes_the_vehicles_signed_telemetry_and_drops_forgeries(
        signed_sim: Simulator) -> None:
    import time

    from agents.mavlink.adapter import AdapterConfig, MavlinkAdapter
    from sim_backend import telemetry as tm
    ep, row = signed_sim.endpoints[0], signed_sim._rows[0]
    forger = new_codec(1, 1)  # the vehicle's own ids, no key
    forged = forger.local_position_ned_encode(0, 500.0, -500.0, -10.0, 0, 0, 0).pack(forger)
    signed = ep.build(tm.MSG_LOCAL_POSITION_NED, row)
    assert signed is not None
    with MavlinkAdapter(AdapterConfig(local_port=0, target_sysid=1, signing_key=KEY)) as ad, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        assert ad.sock is not None
        for frame in (forged, signed):
            tx.sendto(frame, ad.sock.getsockname())
        deadline = time.monotonic() + 5.0
        while ad.counters["signing_rejected_unsigned"] == 0 or not ad.state.link_ok:
            assert time.monotonic() < deadline, ad.counters
            ad.wait_readable(0.05)
            ad.poll()
    assert ad.counters["signing_rejected_unsigned"] == 1
    north, east, down = row.pos
    assert ad.state.pos_enu_m == pytest.approx((east, north, -down))


@pytest.mark.realtime
def test_adapter_setpoints_decode_and_verify_in_stock_pymavlink() -> None:
    """The adapter packs its setpoints by struct: stock pymavlink, keyed, must check their
    signatures and read the fields the adapter meant (ENU (1, 2, 3) is NED (2, 1, -3))."""
    import socket

    from pymavlink.dialects.v20 import common as mavlink2

    from agents.mavlink.adapter import AdapterConfig, MavlinkAdapter
    from agents.mavlink.velocity_setpoint import MASK_VELOCITY, MASK_VELOCITY_YAW

    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(2.0)
    cfg = AdapterConfig(local_port=0, remote_port=vehicle.getsockname()[1], target_sysid=4,
                        signing_key=KEY, signing_link_id=9)
    stock = mavlink2.MAVLink(None, srcSystem=4, srcComponent=1)
    stock.signing.secret_key = KEY  # pymavlink checks signatures only with a key
    try:
        with MavlinkAdapter(cfg) as ad:
            assert ad.send_velocity_enu((1.0, 2.0, 3.0))
            assert ad.send_velocity_enu((1.0, 2.0, 3.0), yaw_enu_rad=0.0)
            got = [stock.parse_buffer(vehicle.recv(1000)) for _ in range(2)]
    finally:
        vehicle.close()
    for msgs, mask, yaw in ((got[0], MASK_VELOCITY, 0.0), (got[1], MASK_VELOCITY_YAW, 1.5707963)):
        assert msgs is not None and len(msgs) == 1
        m = msgs[0]
        assert m.get_type() == "SET_POSITION_TARGET_LOCAL_NED" and m.get_signed()
        assert m.get_link_id() == 9 and m.target_system == 4 and m.target_component == 1
        assert (m.vx, m.vy, m.vz, m.type_mask, m.coordinate_frame) == (2.0, 1.0, -3.0, mask, 1)
        assert abs(m.yaw - yaw) < 1e-6
    assert stock.signing.goodsig_count == 2 and stock.signing.badsig_count == 0


def test_struct_packed_telemetry_verifies_in_stock_pymavlink() -> None:
    """Every stream the simulator packs by struct, signed, passes stock pymavlink's check."""
    from pymavlink.dialects.v20 import common as mavlink2

    from agents.scenario.model import HomeConfig
    from sim_backend import telemetry as tm

    mav = signer(sysid=3)
    row = tm.Row(5000, (1.0, 2.0, -3.0), (0.5, -0.5, 0.1), 0.01, 0.02, 0.3, 0.0, False)
    data = b"".join(tm.fast_bytes(mav, i, row, HomeConfig()) for i in tm.FAST_IDS)
    data += b"".join(tm.status_bytes(mav, i, row, HomeConfig(), "px4", "OFFBOARD", True, 3)
                     or b"" for i in sorted(tm.STATUS_IDS))
    stock = mavlink2.MAVLink(None)
    stock.signing.secret_key = KEY
    msgs = stock.parse_buffer(data) or []
    assert len(msgs) == len(tm.FAST_IDS) + len(tm.STATUS_IDS)
    assert all(m.get_signed() for m in msgs), [m.get_type() for m in msgs]
    assert stock.signing.goodsig_count == len(msgs) and stock.signing.badsig_count == 0
