"""A MAVLink key per vehicle: another vehicle's key is refused and named, a stamp far in
the future is refused without moving the stream, a restarted sender is taken back."""

from __future__ import annotations

import hashlib
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.mavlink.signing import FUTURE_LIMIT, TICKS_PER_S, SignatureVerifier, signing_timestamp
from agents.mavlink.signing_keys import vehicle_key, vehicle_passphrase
from agents.mavlink.wire import encode, new_codec, sign_outgoing
from agents.scenario.model import HomeConfig, VehicleConfig
from deploy.launch.run_secrets import (
    MAVLINK_SECRET_FILE,
    RunSecrets,
    signing_key_file,
    write_mavlink_keys,
)
from sim_backend.runtime import SimConfig, Simulator, grid_spawn_ned

SECRET = bytes(range(100, 132))
NOW_S = 1_800_000_000.0
ARM_DISARM = 400


def signer(key: bytes, stamp_s: float = NOW_S, link_id: int = 0, sysid: int = 245):
    mav = new_codec(sysid, 191)
    sign_outgoing(mav, key, link_id, signing_timestamp(stamp_s))
    return mav


def disarm(mav, target: int = 1) -> bytes:  # type: ignore[no-untyped-def]
    data: bytes = mav.command_long_encode(target, 1, ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0,
                                          0).pack(mav)
    return data


def check(v: SignatureVerifier, frame: bytes, msg_id: int = 76) -> str | None:
    return v.check(frame, msg_id, frame[5], frame[6])


def test_keys_differ_per_vehicle_and_are_the_sha256_of_their_passphrase() -> None:
    keys = {vehicle_key(SECRET, s) for s in range(1, 256)}
    assert len(keys) == 255
    phrase = vehicle_passphrase(SECRET, 3)
    assert len(phrase) == 64 and int(phrase, 16) >= 0
    # What MAVProxy's `signing key <passphrase>` makes of it.
    assert vehicle_key(SECRET, 3) == hashlib.sha256(phrase.encode("ascii")).digest()
    assert vehicle_key(bytes(range(32)), 3) != vehicle_key(SECRET, 3)


def test_each_agent_gets_only_its_own_vehicles_key(tmp_path: Path) -> None:
    write_mavlink_keys(tmp_path, 4, 2)
    secret = (tmp_path / MAVLINK_SECRET_FILE).read_bytes()
    secrets = RunSecrets(tmp_path)
    for name, sysid in (("follower-0", 1), ("follower-3", 4), ("target-0", 5), ("target-1", 6)):
        path = signing_key_file(tmp_path, name)
        assert path.read_bytes() == vehicle_key(secret, sysid)
        assert path.stat().st_mode & 0o077 == 0
        argv = secrets.args_for(name)
        assert argv[argv.index("--signing-key") + 1] == str(path)
        assert str(tmp_path / MAVLINK_SECRET_FILE) not in argv
    sim = secrets.args_for("sim")
    assert sim[sim.index("--signing-secret") + 1] == str(tmp_path / MAVLINK_SECRET_FILE)
    assert "--signing-key" not in secrets.args_for("recorder")


def test_future_stamp_is_refused_without_moving_the_stream() -> None:
    key = vehicle_key(SECRET, 1)
    v = SignatureVerifier(key, clock=lambda: NOW_S)
    ahead = disarm(signer(key, stamp_s=NOW_S + 3600.0))
    assert check(v, ahead) == "future"
    assert v.streams == {} and v.latest == 0
    assert check(v, disarm(signer(key))) is None  # the sender's real frames still pass
    assert check(v, disarm(signer(key, stamp_s=NOW_S + 4.0))) is None  # clock skew: fine
    assert FUTURE_LIMIT == 5 * TICKS_PER_S and v.counters["rejected_future"] == 1


def test_restarted_sender_is_accepted_on_the_same_or_a_new_link() -> None:
    key = vehicle_key(SECRET, 1)
    clock = [NOW_S]
    v = SignatureVerifier(key, clock=lambda: clock[0])
    first = signer(key, stamp_s=NOW_S, link_id=0)
    for _ in range(3):
        assert check(v, encode(first, first.command_long_encode(1, 1, 400, 0, *[0] * 7))) \
            is None
    clock[0] += 2.0  # the agent restarts two seconds later, signing from its wall clock
    assert check(v, disarm(signer(key, stamp_s=clock[0], link_id=0))) is None
    assert check(v, disarm(signer(key, stamp_s=clock[0] - 30.0, link_id=7))) is None
    assert check(v, disarm(signer(key, stamp_s=clock[0] - 1.0, link_id=0))) == "replay"


@pytest.fixture
def secret_sim() -> Iterator[Simulator]:
    s = Simulator(grid_spawn_ned(3), VehicleConfig(), HomeConfig(),
                  SimConfig(listen_base_port=0, send_base_port=9, signing_secret=SECRET))
    try:
        yield s
    finally:
        s.close()


@pytest.mark.realtime
def test_vehicle_refuses_another_vehicles_key_and_names_it(secret_sim: Simulator) -> None:
    ep, row = secret_sim.endpoints[0], secret_sim._rows[0]
    addr = ("127.0.0.1", 9)
    now = time.time()
    # Follower 2's agent (link 2, vehicle 3's key) commands vehicle 1.
    ep.on_datagram(disarm(signer(vehicle_key(SECRET, 3), now, link_id=2)), addr, 0.0, row)
    # A key no vehicle has.
    ep.on_datagram(disarm(signer(bytes(32 * [9]), now, link_id=2)), addr, 0.0, row)
    c = secret_sim.counters
    assert c["signing_rejected_wrong_key"] == 1 and c["signing_wrong_key_vehicle_3"] == 1
    assert c["signing_rejected_bad_signature"] == 1 and c["commands"] == 0
    ep.on_datagram(disarm(signer(vehicle_key(SECRET, 1), now, link_id=0)), addr, 0.0, row)
    assert c["commands"] == 1


@pytest.mark.realtime
def test_vehicle_telemetry_is_signed_with_its_own_key(secret_sim: Simulator) -> None:
    """Vehicle 2's telemetry passes vehicle 2's key and fails vehicle 1's: an agent holding
    vehicle 1's key refuses it, even sent in vehicle 1's name."""
    from agents.mavlink.adapter import AdapterConfig, MavlinkAdapter
    from sim_backend import telemetry as tm
    frame = secret_sim.endpoints[1].build(tm.MSG_LOCAL_POSITION_NED, secret_sim._rows[1])
    assert frame is not None
    assert check(SignatureVerifier(vehicle_key(SECRET, 2)), frame, 32) is None
    assert check(SignatureVerifier(vehicle_key(SECRET, 1)), frame, 32) == "bad_signature"
    forged = vehicle_key(SECRET, 2)
    mav = new_codec(1, 1)  # vehicle 1's ids, vehicle 2's key
    sign_outgoing(mav, forged, 0, signing_timestamp(time.time()))
    fake = encode(mav, mav.local_position_ned_encode(0, 500.0, -500.0, -10.0, 0, 0, 0))
    cfg = AdapterConfig(local_port=0, target_sysid=1, signing_key=vehicle_key(SECRET, 1))
    with MavlinkAdapter(cfg) as ad, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        assert ad.sock is not None
        tx.sendto(fake, ad.sock.getsockname())
        deadline = time.monotonic() + 5.0
        while ad.counters["signing_rejected_bad_signature"] == 0:
            assert time.monotonic() < deadline, ad.counters
            ad.wait_readable(0.05)
            ad.poll()
    assert not ad.telemetry_seen


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_screen_never_changes_state_and_agrees_with_check(data: st.DataObject) -> None:
    """Hostile datagrams: the first-frame screen moves no stream, and what it lets through
    is what the full check accepts (one frame per datagram)."""
    key = vehicle_key(SECRET, 1)
    base = bytearray(disarm(signer(data.draw(st.sampled_from([key, vehicle_key(SECRET, 2)])),
                                   NOW_S + data.draw(st.floats(-120.0, 120.0)),
                                   link_id=data.draw(st.integers(0, 3)))))
    for _ in range(data.draw(st.integers(0, 3))):
        pos = data.draw(st.integers(0, len(base) - 1))
        base[pos] = data.draw(st.integers(0, 255))
    frame = bytes(base[:data.draw(st.integers(0, len(base)))])
    v = SignatureVerifier(key, clock=lambda: NOW_S, allowed_unsigned=frozenset(),
                          key_of_vehicle=lambda s: vehicle_key(SECRET, s))
    seen = disarm(signer(key, NOW_S - 1.0, link_id=1))
    assert check(v, seen) is None
    before = (dict(v.streams), v.latest)
    verdict = v.screen(frame)
    assert (dict(v.streams), v.latest) == before
    if verdict is None:  # nothing passes unsigned here: a whole signed first frame
        end = 12 + frame[1] + 13
        assert frame[2] & 1 and check(v, frame[:end], frame[7] | frame[8] << 8) is None


def test_a_companions_host_folder_holds_its_own_vehicles_keys_only(tmp_path: Path) -> None:
    """Over hosts, a follower's host gets its followers' vehicle keys, not the run secret
    nor another vehicle's key (deploy.hosts.host_keys copies what RunSecrets.args_for names)."""
    from deploy.hosts.deployment import Deployment, HostSpec
    from deploy.hosts.host_keys import write_swarm_keys

    dep = Deployment("field", "paper", (
        HostSpec("ground", "10.0.0.1", ("launcher", "sim", "recorder", "target-0", "target-1")),
        HostSpec("drone-a", "10.0.0.2", ("follower-0", "follower-1")),
        HostSpec("drone-b", "10.0.0.3", ("follower-2", "follower-3"))))
    folders = write_swarm_keys(tmp_path / "creds", dep, 4, 2)
    secret = (tmp_path / "creds" / "operator" / MAVLINK_SECRET_FILE).read_bytes()
    mavlink = {host: sorted(p.name for p in folder.iterdir() if "mavlink" in p.name)
               for host, folder in folders.items()}
    assert mavlink == {
        "ground": [MAVLINK_SECRET_FILE, "target-0.mavlink-key.bin", "target-1.mavlink-key.bin"],
        "drone-a": ["follower-0.mavlink-key.bin", "follower-1.mavlink-key.bin"],
        "drone-b": ["follower-2.mavlink-key.bin", "follower-3.mavlink-key.bin"]}
    assert (folders["drone-b"] / "follower-2.mavlink-key.bin").read_bytes() == \
        vehicle_key(secret, 3)
