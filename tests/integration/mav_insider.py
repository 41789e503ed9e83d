"""A hostile process on the MAVLink side, holding one vehicle's key (what a compromised
agent holds), for the insider test and the flood benchmark.

    python -m tests.integration.mav_insider --seconds T --out report.json \
        [--key FILE --own-sysid K --vehicle-port BASE --vehicles N] \
        [--flood-port P ... --flood-dps R --flood-size B] [--progress PROGRESS_JSON]

- Insider (`--key`): every 0.2 s, to every other vehicle, a force-disarm, a NAV_LAND and a
  velocity setpoint signed with its key, on its agent's link (K-1); counts every
  COMMAND_ACK it gets back, by the vehicle that sent it.  Once, a frame to its own vehicle
  stamped an hour ahead; at the end a command to its own vehicle with a true stamp (is its
  stream still open?).
- Flood (`--flood-port`): R datagrams a second of B bytes each at each port (of
  `--flood-host`, from `--flood-from`, e.g. 127.0.0.2: another address).  `--flood-kind`
  `signed`: MAVLink frames signed with a key nobody holds, in the vehicle's name (sysid 1,
  component 1); `lan`: what anyone on the LAN can send, no key needed: garbage, and
  garbage behind an 8-byte MAVLink 1 HEARTBEAT prefix (id 0, accepted unsigned), alternated.
- `--progress`: a run's progress.json; nothing is sent before the run's experiment starts.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import sys
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

from agents.mavlink.signing import signing_timestamp
from agents.mavlink.signing_keys import load_key
from agents.mavlink.wire import encode, new_codec, sign_outgoing
from agents.mavlink.wire_decode import Codec, decode_datagram
from tests.integration.rogue import wait_running

ARM_DISARM, NAV_LAND, REQUEST_MESSAGE, FORCE = 400, 21, 512, 21196.0
FUTURE_S = 3600.0


def signed_codec(key: bytes, link_id: int, stamp_s: float, sysid: int = 245,
                 compid: int = 191) -> Codec:
    mav = new_codec(sysid, compid)
    sign_outgoing(mav, key, link_id, signing_timestamp(stamp_s))
    return mav


def flood_datagrams(size_b: int, count: int = 8) -> list[bytes]:
    """`count` distinct datagrams of about `size_b` bytes of badly signed frames."""
    mav = signed_codec(os.urandom(32), 0, time.time(), sysid=1, compid=1)
    out = []
    for k in range(count):
        data = b""
        while True:
            frame = encode(mav, mav.local_position_ned_encode(k, 1.0, 2.0, -3.0, 0, 0, 0))
            if data and len(data) + len(frame) > size_b:
                break
            data += frame
        out.append(data)
    return out


HEARTBEAT_PREFIX_V1 = b"\xfe\x09\x00\x01\x01\x00\x00\x00"  # 8 bytes: len 9, id 0


def lan_datagrams(size_b: int, count: int = 8) -> list[bytes]:
    """`count` datagrams of `size_b` bytes: garbage, and garbage behind a HEARTBEAT prefix."""
    out = []
    for k in range(count):
        body = os.urandom(max(1, size_b))
        out.append(HEARTBEAT_PREFIX_V1 + body[len(HEARTBEAT_PREFIX_V1):] if k % 2 else body)
    return out


class Flooder:
    """Paced sends of `datagrams` round-robin to `ports`, at `rate_dps` in total."""

    def __init__(self, ports: Sequence[int], rate_dps: float, size_b: int, kind: str = "signed",
                 host: str = "127.0.0.1", source: str | None = None) -> None:
        self.targets = [(host, p) for p in ports]
        self.rate_dps = rate_dps
        make = lan_datagrams if kind == "lan" else flood_datagrams
        self.datagrams = make(size_b) if ports and rate_dps > 0 else []
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        if source is not None:
            self.sock.bind((source, 0))
        self.sock.setblocking(False)
        self.sent = self.bytes = self.errors = 0
        self.t0 = time.monotonic()

    def due(self) -> None:
        if not self.datagrams:
            return
        want = int((time.monotonic() - self.t0) * self.rate_dps)
        while self.sent < want:
            data = self.datagrams[self.sent % len(self.datagrams)]
            try:
                self.sock.sendto(data, self.targets[self.sent % len(self.targets)])
                self.bytes += len(data)
            except OSError:
                self.errors += 1
            self.sent += 1


class Insider:
    """Commands signed with vehicle `own`'s key to the others; a future stamp to its own."""

    def __init__(self, key: bytes, own: int, vehicle_base: int, vehicles: int) -> None:
        self.own, self.base, self.n = own, vehicle_base, vehicles
        self.key = key
        self.mav = signed_codec(key, own - 1, time.time())
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.report: Counter[str] = Counter()

    def port(self, sysid: int) -> tuple[str, int]:
        return ("127.0.0.1", self.base + sysid - 1)

    def future_frame(self) -> None:
        ahead = signed_codec(self.key, self.own - 1, time.time() + FUTURE_S)
        self.sock.sendto(self._request(ahead), self.port(self.own))
        self.report["future_sent"] += 1

    def _request(self, mav: Codec) -> bytes:  # REQUEST_MESSAGE(HEARTBEAT): answered by an ACK
        return encode(mav, mav.command_long_encode(self.own, 1, REQUEST_MESSAGE, 0, 0, 0, 0,
                                                   0, 0, 0, 0))

    def attack(self) -> None:
        for sysid in range(1, self.n + 1):
            if sysid == self.own:
                continue
            m = self.mav
            for msg in (m.command_long_encode(sysid, 1, ARM_DISARM, 0, 0, FORCE, 0, 0, 0, 0, 0),
                        m.command_long_encode(sysid, 1, NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0),
                        m.set_position_target_local_ned_encode(0, sysid, 1, 1, 3527, 0, 0, 0,
                                                               5.0, 5.0, 2.0, 0, 0, 0, 0, 0)):
                self.sock.sendto(encode(m, msg), self.port(sysid))
                self.report["signed_sent_to_others"] += 1
        self.read_acks()

    def read_acks(self) -> None:
        while True:
            try:
                data = self.sock.recv(65535)
            except BlockingIOError:
                return
            for msg in decode_datagram(self.mav, data).messages:
                if msg.get_type() == "COMMAND_ACK":
                    who = "own" if msg.get_srcSystem() == self.own else "others"
                    self.report[f"acks_{who}"] += 1

    def last_word(self) -> None:
        """A true-stamped command to its own vehicle: the future stamp must not have shut
        the stream (its ACK shows in acks_own)."""
        self.sock.sendto(self._request(self.mav), self.port(self.own))
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline and not self.report["acks_own"]:
            time.sleep(0.02)
            self.read_acks()


def run(args: argparse.Namespace) -> dict[str, float]:
    if args.progress is not None:
        wait_running(Path(args.progress))
    flooder = Flooder(args.flood_port, args.flood_dps, args.flood_size, args.flood_kind,
                      args.flood_host, args.flood_from)
    insider = None if args.key is None else Insider(load_key(args.key), args.own_sysid,
                                                    args.vehicle_port, args.vehicles)
    if insider is not None:
        insider.future_frame()
    t0 = time.monotonic()
    next_attack = t0
    while time.monotonic() - t0 < args.seconds:
        flooder.due()
        if insider is not None and time.monotonic() >= next_attack:
            next_attack += 0.2
            insider.attack()
        time.sleep(0.002)
    if insider is not None:
        insider.last_word()
    t = os.times()
    report: dict[str, float] = {"flood_sent": flooder.sent, "flood_bytes": flooder.bytes,
                                "flood_errors": flooder.errors, "seconds": args.seconds,
                                "cpu_s": t.user + t.system}
    if insider is not None:
        report.update(insider.report)
    return report


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--seconds", type=float, required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--key", default=None, help="the vehicle key this insider holds")
    p.add_argument("--own-sysid", type=int, default=1)
    p.add_argument("--vehicle-port", type=int, default=14580)
    p.add_argument("--vehicles", type=int, default=1)
    p.add_argument("--flood-port", type=int, action="append", default=[])
    p.add_argument("--flood-dps", type=float, default=0.0, help="datagrams a second, in all")
    p.add_argument("--flood-size", type=int, default=65000, help="bytes per datagram")
    p.add_argument("--flood-kind", choices=("signed", "lan"), default="signed")
    p.add_argument("--flood-host", default="127.0.0.1", help="the address flooded")
    p.add_argument("--flood-from", default=None, help="the address flooded from")
    p.add_argument("--progress", default=None, help="a run's progress.json: wait for its start")
    args = p.parse_args(argv)
    report = run(args)
    with open(args.out, "w") as out:
        json.dump(report, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
