"""A MAVLink receiver's path in one pass per datagram, for the frames sent to it at rate.

The layered path (RxGate's screen of the first frame, `decode_datagram` into pymavlink
message objects, `signature_ok` per message) costs a follower ~25 Python calls and a dozen
objects per frame; at 50 Hz that was most of its MAVLink work (issue 50).  `FastRx.scan`
walks a datagram once: each frame's header, CRC, signature and stream check inline,
LOCAL_POSITION_NED's fields unpacked straight from the payload, no message object.

It takes only frames it judges exactly as the layered path does: MAVLink 2 frames of the
types `decode_datagram` decodes by struct (FAST_IDS), signed when a verifier is set.  At
the first frame it cannot judge so (MAVLink 1, unsigned, another type, a bad CRC, a cut
frame) it stops, and the layered path takes the datagram from there: for the first frame
that means all of it, screen included.  So verdicts, counters and the order in which
messages reach the receiver equal the layered path's (tests/unit/test_mavlink_fast_rx.py,
tests/unit/test_sim_fast_rx.py).
A refused first frame is what the screen would refuse: the datagram is dropped unparsed.
"""

from __future__ import annotations

import struct
from collections import Counter
from typing import Any

from agents.mavlink.digest import compare_digest
from agents.mavlink.rx_gate import Addr, RxGate
from agents.mavlink.signing import SignatureVerifier, keyed_sha256
from agents.mavlink.wire_decode import FAST_IDS, Codec, dialect_tables

LOCAL_POSITION_NED = 32
SET_POSITION_TARGET_LOCAL_NED = 84
_HEADER = struct.Struct("<BBBBBBBHB")
# (msg id, sysid, compid, the unpacked type's fields in wire order or the frame's bytes)
Accepted = tuple[int, int, int, Any]


class FastRx:
    """One vehicle link's one-pass reader: `scan(datagram)` (module docstring).

    `counters`: the receiver's, for what scan decides past the first frame (rejections
    as signing_rejected_<reason>, frames of types the dialect lacks as unknown_types);
    `unpacked`: the message id whose fields come unpacked (one of FAST_IDS)."""

    __slots__ = (
        "counters",
        "crc",
        "extras",
        "flags",
        "hasher",
        "known",
        "unpacked",
        "unpacker",
        "verifier",
    )

    def __init__(self, mav: Codec, verifier: SignatureVerifier | None,
                 counters: Counter[str], unpacked: int = LOCAL_POSITION_NED) -> None:
        tables = dialect_tables(mav)
        self.extras = {i: tables.fast[i].extra for i in FAST_IDS if i in tables.fast}
        self.known = tables.known
        self.crc = tables.crc
        self.unpacked = unpacked
        self.unpacker: struct.Struct = tables.fast[unpacked].cls.unpacker
        self.verifier = verifier
        self.hasher = None if verifier is None else keyed_sha256(verifier.key)
        self.counters = counters
        # Incompatibility flags taken: signed only, when signatures are checked.
        self.flags = (1,) if verifier is not None else (0, 1)

    def read(self, gate: RxGate, data: bytes, sender: Addr,
             stamp: float) -> tuple[list[Accepted], bytes]:
        """A datagram off the socket, charged to `gate`: (the frames this pass accepted, the
        part of it the layered path takes, b"" for none).  A datagram that does not fit the
        tick's parse budget, or whose first frame is not this pass's, is all the gate's
        (`RxGate.admit`: screened, cut or carried to the next tick); one whose first frame
        is refused is dropped here as the screen would drop it."""
        rest, refused = 0, None
        if gate.fits(len(data)):
            accepted, rest, refused = self.scan(data)
        if refused is not None:
            gate.refuse(refused, sender)
            return [], b""
        if rest == 0:
            return [], gate.admit(data, sender, stamp) or b""
        gate.take(len(data))
        return accepted, data[rest:]

    def scan(self, data: bytes) -> tuple[list[Accepted], int, str | None]:
        """(the frames accepted, in order; where the layered path takes over: len(data)
        when nowhere, 0 when the whole datagram is its; the reason the first frame is
        refused, None if it is not)."""
        accepted: list[Accepted] = []
        i, n, crc, hasher = 0, len(data), self.crc, self.hasher
        while i < n - 11 and data[i] == 0xFD:
            _, mlen, flags, _, _, sysid, compid, msg_id, high = _HEADER.unpack_from(data, i)
            crc_at = i + 10 + mlen
            end = crc_at + (15 if flags else 2)
            extra = self.extras.get(msg_id)
            if flags not in self.flags or end > n or high:
                break
            if extra is None:
                if i == 0 or msg_id in self.known:
                    break
                self.counters["unknown_types"] += 1  # framed, not checkable: as decode does
                i = end
                continue
            if crc(data[i + 1:crc_at] + extra, 0xFFFF) != data[crc_at] | data[crc_at + 1] << 8:
                break
            if hasher is not None:
                reason = self._verdict(data, i, crc_at, end, sysid, compid)
                if reason is not None:
                    if i == 0:
                        return accepted, 0, reason
                    assert self.verifier is not None
                    self.verifier.count_rejection(reason, self.counters)
                    i = end
                    continue
            body: Any
            if msg_id == self.unpacked:
                fmt = self.unpacker  # MAVLink 2 cuts trailing zeros; a newer dialect adds
                body = fmt.unpack_from(data, i + 10) if mlen == fmt.size else fmt.unpack(
                    data[i + 10:crc_at][:fmt.size].ljust(fmt.size, b"\0"))
            else:
                body = data[i:end]
            accepted.append((msg_id, sysid, compid, body))
            i = end
        return accepted, i, None

    def _verdict(self, data: bytes, i: int, crc_at: int, end: int, sysid: int,
                 compid: int) -> str | None:
        """The verifier's verdict on the signed frame data[i:end], its stream moved if good."""
        verifier = self.verifier
        assert verifier is not None and self.hasher is not None
        sig_at = end - 6
        digest = self.hasher.copy()
        digest.update(data[i:sig_at])
        if not compare_digest(digest.digest()[:6], data[sig_at:end]):
            return verifier.refuse_signature(data[i:sig_at], data[sig_at:end], data[crc_at + 2])
        return verifier.accept(data[crc_at + 2], sysid, compid,
                               int.from_bytes(data[crc_at + 3:sig_at], "little"))
