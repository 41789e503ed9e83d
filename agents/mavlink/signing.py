"""MAVLink 2 message signing: the key file, and a verifier that checks before it trusts.

Signature block (devguide message_signing): link id (1 byte), timestamp (6 bytes,
10 µs units since 2015-01-01 UTC), signature = first 6 bytes of
sha256(key + frame up to and including the timestamp).

Why our own verifier and not pymavlink's: pymavlink 2.4.50 stores a stream's
timestamp *before* it checks the signature, so one forged packet with a future
timestamp and the right (link id, sysid, compid) locks the real sender out for good
(measured: notes/security.md).  Here the signature is checked first; only a good one
moves a stream's timestamp.  Replays (timestamp not above the stream's last) and new
streams more than a minute behind our time are rejected, as the spec says.  Messages
PX4 always accepts unsigned (HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE, COLLISION) pass.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

from transport.errors import ConfigError

KEY_LEN = 32
SIGNATURE_LEN = 13
IFLAG_SIGNED = 0x01
STX_V2 = 0xFD
EPOCH_2015_S = 1420070400.0
TICKS_PER_S = 100_000  # timestamp unit: 10 µs
NEW_STREAM_WINDOW = 60 * TICKS_PER_S
# PX4 accepts these unsigned on a signing link (message_signing docs).
ALLOWED_UNSIGNED = frozenset({0, 109, 246, 247})  # HEARTBEAT, RADIO_STATUS, ADSB, COLLISION


def signing_timestamp(unix_s: float) -> int:
    """A signing timestamp (10 µs ticks since 2015-01-01 UTC) from Unix seconds."""
    return max(0, int((unix_s - EPOCH_2015_S) * TICKS_PER_S))


def write_key(path: Path) -> bytes:
    """A fresh random 32-byte key, written raw to `path` with 0600 rights from the start."""
    key = os.urandom(KEY_LEN)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as out:
        out.write(key)
    os.chmod(path, 0o600)
    return key


def key_from_passphrase(passphrase: str) -> bytes:
    """MAVProxy's `signing setup <passphrase>` key: sha256 of the passphrase."""
    return hashlib.sha256(passphrase.encode()).digest()


def load_key(path: str | Path) -> bytes:
    """The 32 raw bytes of a key file; an all-zero key would disable signing: refused."""
    try:
        key = Path(path).read_bytes()
    except OSError as exc:
        raise ConfigError("signing_key", f"{path}: {exc.strerror}") from exc
    if len(key) != KEY_LEN:
        raise ConfigError("signing_key", f"{path} holds {len(key)} bytes, a key is {KEY_LEN}")
    if not any(key):
        raise ConfigError("signing_key", f"{path} is all zeros (that disables signing)")
    return key


# A sha256 that has taken each key, copied per frame: the key is hashed once per key, not
# once per frame (signing and checking run at the control rate).  Keys are configured, few.
_KEYED: dict[bytes, Any] = {}


def signature(key: bytes, frame_to_timestamp: bytes) -> bytes:
    """MAVLink 2's signature: sha256(key + frame up to its timestamp), first 6 bytes."""
    base = _KEYED.get(key)
    if base is None:
        base = _KEYED[key] = hashlib.sha256(key)
    digest = base.copy()
    digest.update(frame_to_timestamp)
    return digest.digest()[:6]


class SignatureVerifier:
    """Accepts or rejects received frames; one per link end (vehicle), not thread-safe.

    `check(frame, msg_id, sysid, compid)` returns None when accepted, else the reason
    (`unsigned`, `bad_signature`, `replay`), also counted in `counters` as rejected_<reason>.
    """

    def __init__(self, key: bytes, clock: Callable[[], float] = time.time,
                 allowed_unsigned: frozenset[int] = ALLOWED_UNSIGNED) -> None:
        if len(key) != KEY_LEN:
            raise ConfigError("signing_key", f"a key is {KEY_LEN} bytes")
        self.key = key
        self.clock = clock
        self.allowed_unsigned = allowed_unsigned
        self.streams: dict[tuple[int, int, int], int] = {}
        self.latest = 0  # highest timestamp seen in a good signature
        self.counters: Counter[str] = Counter()

    def now_ticks(self) -> int:
        return max(self.latest, signing_timestamp(self.clock()))

    def check(self, frame: bytes, msg_id: int, sysid: int, compid: int) -> str | None:
        reason = self._reason(frame, msg_id, sysid, compid)
        self.counters["accepted_signed" if reason is None and _signed(frame) else
                      "accepted_unsigned" if reason is None else f"rejected_{reason}"] += 1
        return reason

    def _reason(self, frame: bytes, msg_id: int, sysid: int, compid: int) -> str | None:
        if not _signed(frame):
            return None if msg_id in self.allowed_unsigned else "unsigned"
        if len(frame) < 12 + SIGNATURE_LEN:
            return "bad_signature"
        # Signature first: nothing about a badly signed frame may change our state.
        if not hmac.compare_digest(signature(self.key, frame[:-6]), frame[-6:]):
            return "bad_signature"
        link_id = frame[-SIGNATURE_LEN]
        stamp = int.from_bytes(frame[-12:-6], "little")
        stream = (link_id, sysid, compid)
        last = self.streams.get(stream)
        if last is not None and stamp <= last:
            return "replay"
        if last is None and stamp + NEW_STREAM_WINDOW < self.now_ticks():
            return "replay"
        self.streams[stream] = stamp
        self.latest = max(self.latest, stamp)
        return None


def _signed(frame: bytes) -> bool:
    return len(frame) > 2 and frame[0] == STX_V2 and bool(frame[2] & IFLAG_SIGNED)
