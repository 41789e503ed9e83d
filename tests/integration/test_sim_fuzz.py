"""Fuzz: 10^5 random and mutated MAVLink 2 messages of every handled type over real UDP.

Vehicle 1 takes the fuzz; meanwhile a pymavlink GCS flies vehicle 2 in OFFBOARD.  The
simulator must stay up, vehicle 2 must keep flying its setpoints, vehicle 1 must still
answer afterwards, and every message must appear in the simulator's per-message counts.
"""

from __future__ import annotations

import math
import random
import socket
import struct
import time

import pytest

from agents.mavlink.wire import new_codec
from agents.mavlink.wire_decode import decode_datagram
from tests.integration.sim_process import HOST, PlainClient, message_outcomes, start_sim
from tests.mavlink_fuzz import (
    HANDLED_CLASSES,
    message_class,
    payload_size,
    raw_frame,
    target_offset,
)

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]

TOTAL = 100_000
PER_DATAGRAM = 25
DATAGRAMS_PER_SYNC = 8
COMMANDS = (20, 21, 22, 176, 192, 400, 410, 510, 511, 512, 519, 520, 31000)
SPECIAL = (math.nan, math.inf, -math.inf, 0.0, 1.0, -1.0, 21196.0, 6.0, 4.0, 1e30, 148.0, 24.0)
COMMAND_LONG = message_class("COMMAND_LONG")
SET_MODE = message_class("SET_MODE")


class Fuzzer:
    def __init__(self, seed: int) -> None:
        self.rng = random.Random(seed)
        self.valid = 0
        self.corrupt = 0

    def _value(self) -> float:
        rng = self.rng
        return rng.choice(SPECIAL) if rng.random() < 0.5 else rng.uniform(-1e6, 1e6)

    def message(self) -> bytes:
        rng = self.rng
        roll = rng.random()
        if roll < 0.2:  # a command with spec-special values in its params
            params = [self._value() for _ in range(7)]
            payload = struct.pack("<7fHBBB", *params, rng.choice(COMMANDS), rng.choice((0, 1)),
                                  1, rng.randrange(3))
            return raw_frame(COMMAND_LONG, payload, rng.randrange(256))
        if roll < 0.3:  # SET_MODE naming any custom mode
            payload = struct.pack("<IBB", rng.getrandbits(32), rng.choice((0, 1)),
                                  rng.randrange(256))
            return raw_frame(SET_MODE, payload, rng.randrange(256))
        cls = rng.choice(HANDLED_CLASSES)
        payload = bytearray(rng.randbytes(payload_size(cls)))
        offset = target_offset(cls)
        if offset is not None and rng.random() < 0.8:  # mostly addressed to vehicle 1
            payload[offset] = rng.choice((0, 1))
        payload = payload[:rng.randrange(1, len(payload) + 1)]  # MAVLink 2 truncation
        return raw_frame(cls, bytes(payload), rng.randrange(256))

    def datagram(self) -> tuple[bytes, int]:
        """PER_DATAGRAM messages; sometimes the last one mutated after its CRC (corrupt)."""
        frames = [self.message() for _ in range(PER_DATAGRAM)]
        if self.rng.random() < 0.3:
            last = bytearray(frames[-1])
            last[self.rng.randrange(1, len(last))] ^= 1 << self.rng.randrange(8)
            frames[-1] = bytes(last)
            self.corrupt += 1
            return b"".join(frames), PER_DATAGRAM - 1
        return b"".join(frames), PER_DATAGRAM


def sync(sock: socket.socket, vehicle: tuple[str, int], seq: int) -> int:
    """PING vehicle 1 and wait for the reply: every datagram sent before is then handled."""
    mav = new_codec(254, 190)
    pings = 0
    while True:
        sock.sendto(mav.ping_encode(seq, seq, 0, 0).pack(mav), vehicle)
        pings += 1
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            try:
                data, _ = sock.recvfrom(65535)
            except TimeoutError:
                continue
            if data[:1] == b"\xfd" and data[7:10] == b"\x04\x00\x00" and \
                    any(m.seq == seq for m in decode_datagram(mav, data).messages):
                return pings
        assert pings < 5, "vehicle 1 stopped answering PING"


def test_fuzz_keeps_simulator_up_and_vehicles_flying() -> None:
    sim = start_sim(vehicles=2)
    gcs = PlainClient(sim.send_base + 1, sim.listen_base + 1, target_sysid=2)
    fuzz_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    fuzz_sock.bind((HOST, 0))
    fuzz_sock.settimeout(0.05)
    vehicle1 = (HOST, sim.listen_base)
    gcs_sent = 0

    def fly() -> None:
        nonlocal gcs_sent
        gcs.send(gcs.mav.set_position_target_local_ned_encode(
            0, 2, 1, 1, 3527, 0, 0, 0, 1.0, 0.0, -0.5, 0, 0, 0, 0, 0))
        gcs_sent += 1

    fuzzer = Fuzzer(seed=11)
    pings = 0
    try:
        gcs.until(lambda: "HEARTBEAT" in gcs.last and "LOCAL_POSITION_NED" in gcs.last, 10.0,
                  "vehicle 2 telemetry")
        assert gcs.command(400, 1) == 0
        fly()
        assert gcs.command(176, 1, 6, 0) == 0
        gcs_sent += 2
        gcs.until(lambda: gcs.last["HEARTBEAT"].custom_mode == 6 << 16, 2.0, "OFFBOARD",
                  every=fly)
        start = time.monotonic()
        pos0 = gcs.last["LOCAL_POSITION_NED"]
        sent = 0
        last_fly = 0.0
        while sent < TOTAL:
            for _ in range(DATAGRAMS_PER_SYNC):
                data, valid = fuzzer.datagram()
                fuzz_sock.sendto(data, vehicle1)
                fuzzer.valid += valid
                sent += PER_DATAGRAM
            pings += sync(fuzz_sock, vehicle1, sent)
            if time.monotonic() - last_fly > 0.1:
                last_fly = time.monotonic()
                fly()
                gcs.drain()
        fuzz_s = time.monotonic() - start
        # Vehicle 2 flew its setpoints all along: still OFFBOARD, moved north at ~1 m/s.
        fly()
        gcs.drain()
        pos = gcs.last["LOCAL_POSITION_NED"]
        assert gcs.last["HEARTBEAT"].custom_mode == 6 << 16
        # Sim time may fall behind wall time on a loaded machine (counted as overruns), but
        # it keeps running, and in sim time the vehicle flew its 1 m/s all along.
        sim_s = (pos.time_boot_ms - pos0.time_boot_ms) * 1e-3
        assert sim_s > 0.2 * fuzz_s
        assert pos.x - pos0.x == pytest.approx(sim_s, rel=0.1)
        assert pos.vx == pytest.approx(1.0, abs=0.1)
        # Vehicle 1 still answers commands.
        probe = PlainClient(sim.send_base, sim.listen_base)
        try:
            assert probe.command(512, 148) == 0
        finally:
            probe.close()
        gcs_sent += 1
    finally:
        fuzz_sock.close()
        gcs.close()
        code = sim.stop()
    assert code == 0
    out = sim.output()
    outcomes = message_outcomes(out)
    counted = sum(outcomes.values())
    print(f"fuzz: {sent} messages in {fuzz_s:.1f} s, {fuzzer.corrupt} corrupt frames, "
          f"outcomes {outcomes}")
    assert not any(k.endswith(":failed") for k in outcomes), outcomes
    # Every valid message the fuzzer, the GCS and the probes sent was counted once.
    assert counted >= fuzzer.valid + pings + gcs_sent
    assert counted <= fuzzer.valid + pings + gcs_sent + 200  # + GCS heartbeats, retries
    refused = sum(v for k, v in outcomes.items() if k.endswith((":refused", ":ignored")))
    assert refused > 0 and "bad_packets=" in out and "handler_errors" not in out
