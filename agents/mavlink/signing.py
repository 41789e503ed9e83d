"""MAVLink 2 message signing: a verifier that checks before it trusts.

Signature block (devguide message_signing): link id (1 byte), timestamp (6 bytes,
10 µs units since 2015-01-01 UTC), signature = first 6 bytes of
sha256(key + frame up to and including the timestamp).

Why our own verifier and not pymavlink's: pymavlink 2.4.50 stores a stream's
timestamp *before* it checks the signature, so one forged packet with a future
timestamp and the right (link id, sysid, compid) locks the real sender out for good
(measured: notes/security.md).  Here the signature is checked first; only a good one
moves a stream's timestamp.  Replays (timestamp not above the stream's last) and new
streams more than a minute behind our time are rejected, as the spec says; so are frames
stamped more than FUTURE_LIMIT ahead of our clock, without moving any stream: a frame
stamped a day ahead, even correctly signed, would otherwise make its stream refuse the
sender's real frames for a day.  A new stream (a restarted sender, on a new link id or
with timestamps that continue on the wall clock) is accepted.  Messages PX4 always accepts
unsigned (HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE, COLLISION) pass.

A key per vehicle, derived from a run secret, comes from agents.mavlink.signing_keys.  A
vehicle that knows the other vehicles' keys tells a frame signed with one of them
(`wrong_key`, and whose) from one signed with no key it knows (`bad_signature`).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from agents.mavlink.digest import compare_digest, sha256
from agents.mavlink.signing_keys import KEY_LEN
from errors import ConfigError

SIGNATURE_LEN = 13
IFLAG_SIGNED = 0x01
STX_V2, STX_V1 = 0xFD, 0xFE
EPOCH_2015_S = 1420070400.0
TICKS_PER_S = 100_000  # timestamp unit: 10 µs
NEW_STREAM_WINDOW = 60 * TICKS_PER_S
# Clocks of signing hosts agree to well under a second (NTP); a few seconds of slack.
FUTURE_LIMIT = 5 * TICKS_PER_S
# Streams a verifier remembers.  A vehicle hears a handful (its agent, a ground station, a
# MAVProxy); the (link id, sysid, compid) triple is the sender's choice, so a key holder
# could otherwise grow the table by one entry per frame.  The least recently accepted
# stream is forgotten beyond this (SignatureVerifier: why that lets no replay through).
MAX_STREAMS = 256
# PX4 accepts these unsigned on a signing link (message_signing docs).
ALLOWED_UNSIGNED = frozenset({0, 109, 246, 247})  # HEARTBEAT, RADIO_STATUS, ADSB, COLLISION


def signing_timestamp(unix_s: float) -> int:
    """A signing timestamp (10 µs ticks since 2015-01-01 UTC) from Unix seconds."""
    return max(0, int((unix_s - EPOCH_2015_S) * TICKS_PER_S))


# A sha256 that has taken each key, copied per frame: the key is hashed once per key, not
# once per frame (signing and checking run at the control rate).  Keys are configured, few.
_KEYED: dict[bytes, Any] = {}


def keyed_sha256(key: bytes) -> Any:
    """A sha256 that has taken `key`: copy it, then update it with a frame."""
    base = _KEYED.get(key)
    if base is None:
        base = _KEYED[key] = sha256(key)
    return base


def signature(key: bytes, frame_to_timestamp: bytes) -> bytes:
    """MAVLink 2's signature: sha256(key + frame up to its timestamp), first 6 bytes."""
    digest = keyed_sha256(key).copy()
    digest.update(frame_to_timestamp)
    return digest.digest()[:6]


class SignatureVerifier:
    """Accepts or rejects received frames; one per link end (vehicle), not thread-safe.

    `check(frame, msg_id, sysid, compid)` returns None when accepted, else the reason
    (`unsigned`, `bad_signature`, `wrong_key`, `future`, `replay`), also counted in
    `counters` as rejected_<reason>.  `screen(datagram)` judges a datagram's first frame
    the same way without changing any state: a receiver drops a datagram it refuses
    unparsed (a flood of badly signed frames costs one hash per datagram).

    `key_of_vehicle` (sysid -> key, or None): the keys of the other vehicles, known to a
    receiver that holds them all (the simulator).  A frame on link k that fails our key is
    tried against vehicle k+1's key alone (the agent of vehicle index k signs on link k):
    one more hash, and a match names whose key signed it (`wrong_key_sysid`).

    `streams` holds at most `max_streams` entries, least recently accepted first; beyond
    it the first is evicted, counted in `counters["streams_evicted"]` and, if given, in the
    receiver's `evictions` counters as `signing_streams_evicted`.  Why no replay gets
    through: `evicted_floor` keeps the highest timestamp ever evicted, and a stream not in
    the table must be stamped above it.  Every frame an evicted stream ever sent is stamped
    at or below its last accepted one, so at or below the floor: none is taken back as a
    "new stream", which the spec alone would allow for a minute.  The price falls on new
    streams stamped at or below the floor, i.e. not past the newest frame evicted: a
    restarted sender stamps from its wall clock, past it, unless the evicted frame was
    stamped ahead, which only a key holder can do and at most FUTURE_LIMIT ahead (the same
    few seconds it can already hold any stream of that key back by).  Only a key holder
    can fill the table (a stream enters on a good signature only), and the stream it
    pushes out was one it could speak for anyway.
    """

    def __init__(self, key: bytes, clock: Callable[[], float] = time.time,
                 allowed_unsigned: frozenset[int] = ALLOWED_UNSIGNED,
                 key_of_vehicle: Callable[[int], bytes | None] | None = None,
                 evictions: Counter[str] | None = None,
                 max_streams: int = MAX_STREAMS) -> None:
        if len(key) != KEY_LEN:
            raise ConfigError("signing_key", f"a key is {KEY_LEN} bytes")
        self.key = key
        self.clock = clock
        self.allowed_unsigned = allowed_unsigned
        self.key_of_vehicle = key_of_vehicle
        if max_streams < 1:
            raise ConfigError("max_streams", f"must be at least 1, got {max_streams}")
        # Insertion order is recency: an accepted frame moves its stream to the end.
        self.streams: dict[tuple[int, int, int], int] = {}
        self.max_streams = max_streams
        self.evicted_floor = 0  # highest timestamp of a stream evicted (class docstring)
        self.evictions = evictions
        self.latest = 0  # highest timestamp seen in a good signature
        self.wrong_key_sysid = 0  # the vehicle whose key signed the last `wrong_key` frame
        self.counters: Counter[str] = Counter()
        # The signed part and signature `screen` last found good: `check` of that same frame
        # (the datagram's first, parsed next) is not hashed twice.  Equal bytes under the
        # same key give the same signature, so this skips work, never a verdict; the stream
        # checks (replay, future) still run.
        self._good_sig: tuple[bytes, bytes] | None = None

    def now_ticks(self) -> int:
        return max(self.latest, signing_timestamp(self.clock()))

    def check(self, frame: bytes, msg_id: int, sysid: int, compid: int) -> str | None:
        reason = self._reason(frame, msg_id, sysid, compid, commit=True)
        self.counters["accepted_signed" if reason is None and _signed(frame) else
                      "accepted_unsigned" if reason is None else f"rejected_{reason}"] += 1
        return reason

    def screen(self, data: bytes) -> str | None:
        """The verdict `check` would give the first frame of datagram `data` (`malformed`
        when it starts with no whole frame), without moving any stream."""
        n = len(data)
        if n < (12 if data[:1] == b"\xfd" else 8) or data[0] not in (STX_V2, STX_V1):
            reason: str | None = "malformed"
        elif data[0] == STX_V1:
            reason = None if data[5] in self.allowed_unsigned else "unsigned"
        else:
            end = 12 + data[1] + (SIGNATURE_LEN if data[2] & IFLAG_SIGNED else 0)
            msg_id = data[7] | data[8] << 8 | data[9] << 16
            reason = "malformed" if end > n else self._reason(
                data[:end], msg_id, data[5], data[6], commit=False)
        if reason is not None:
            self.counters[f"rejected_{reason}"] += 1
        return reason

    def count_rejection(self, reason: str, counters: Counter[str]) -> None:
        """Count a rejection in a receiver's counters: signing_rejected_<reason>, and for a
        frame signed with another vehicle's key, whose (signing_wrong_key_vehicle_<sysid>)."""
        counters[f"signing_rejected_{reason}"] += 1
        if reason == "wrong_key":
            counters[f"signing_wrong_key_vehicle_{self.wrong_key_sysid}"] += 1

    def _reason(self, frame: bytes, msg_id: int, sysid: int, compid: int,
                commit: bool) -> str | None:
        if not _signed(frame):
            return None if msg_id in self.allowed_unsigned else "unsigned"
        if len(frame) < 12 + SIGNATURE_LEN:
            return "bad_signature"
        # Signature first: nothing about a badly signed frame may change our state.
        signed_part, link_id, sig = frame[:-6], frame[-SIGNATURE_LEN], frame[-6:]
        memo = self._good_sig
        if memo is not None and memo[0] == signed_part and compare_digest(memo[1], sig):
            if commit:
                self._good_sig = None
        elif compare_digest(signature(self.key, signed_part), sig):
            if not commit:
                self._good_sig = (signed_part, sig)
        else:
            return self._signature_reason(signed_part, sig, link_id)
        return self._stream_reason((link_id, sysid, compid),
                                   int.from_bytes(frame[-12:-6], "little"), commit)

    def accept(self, link_id: int, sysid: int, compid: int, stamp: int) -> str | None:
        """`check` of a signed frame whose signature the caller found good under `key`
        (agents.mavlink.fast_rx): the stream checks, the stream moved on success, counted."""
        stream, streams = (link_id, sysid, compid), self.streams
        last = streams.get(stream)
        # The common case inline (`_stream_reason`, `_remember`): a known stream moving on.
        if last is not None and last < stamp <= signing_timestamp(self.clock()) + FUTURE_LIMIT:
            del streams[stream]
            streams[stream] = stamp
            if stamp > self.latest:
                self.latest = stamp
            self.counters["accepted_signed"] += 1
            return None
        reason = self._stream_reason(stream, stamp, True)
        self.counters["accepted_signed" if reason is None else f"rejected_{reason}"] += 1
        return reason

    def refuse_signature(self, signed_part: bytes, sig: bytes, link_id: int) -> str:
        """`check`'s reason for a signed frame whose signature failed `key`, counted."""
        reason = self._signature_reason(signed_part, sig, link_id)
        self.counters[f"rejected_{reason}"] += 1
        return reason

    def _signature_reason(self, signed_part: bytes, sig: bytes, link_id: int) -> str:
        return "wrong_key" if self._other_vehicles_key(signed_part, sig,
                                                       link_id) else "bad_signature"

    def _stream_reason(self, stream: tuple[int, int, int], stamp: int,
                       commit: bool) -> str | None:
        wall = signing_timestamp(self.clock())
        if stamp > wall + FUTURE_LIMIT:
            return "future"
        last = self.streams.get(stream)
        if last is not None and stamp <= last:
            return "replay"
        if last is None and (stamp + NEW_STREAM_WINDOW < max(self.latest, wall)
                             or stamp <= self.evicted_floor):
            return "replay"
        if commit:
            self._remember(stream, stamp, last is None)
        return None

    def _remember(self, stream: tuple[int, int, int], stamp: int, new: bool) -> None:
        streams = self.streams
        if new:
            if len(streams) >= self.max_streams:
                oldest = next(iter(streams))
                self.evicted_floor = max(self.evicted_floor, streams.pop(oldest))
                self.counters["streams_evicted"] += 1
                if self.evictions is not None:
                    self.evictions["signing_streams_evicted"] += 1
        else:
            del streams[stream]  # re-inserted below: the most recently accepted is last
        streams[stream] = stamp
        self.latest = max(self.latest, stamp)

    def _other_vehicles_key(self, signed_part: bytes, sig: bytes, link_id: int) -> bool:
        if self.key_of_vehicle is None:
            return False
        key = self.key_of_vehicle(link_id + 1)
        if key is None or key == self.key or not compare_digest(
                signature(key, signed_part), sig):
            return False
        self.wrong_key_sysid = link_id + 1
        return True


def _signed(frame: bytes) -> bool:
    return len(frame) > 2 and frame[0] == STX_V2 and bool(frame[2] & IFLAG_SIGNED)
