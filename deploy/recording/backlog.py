"""What the recorder has taken off the bus but not yet handled: packed, bounded in bytes.

A sample left queued in Zenoh's ring keeps the receive buffer it arrived in resident.  In
ring64, where each of 67 links brings a message or two per read, that was ~8 KB a queued
sample: a recorder starved for 25 s peaked 130 MB above its ~100 MB, and its rings, once
full, lost the oldest samples.  So the recorder empties every ring on every step into a
`Backlog` (no decoding: a few µs a sample) and handles up to a batch of each key per step
from it.

Queued here, a sample is its key, payload and stamps packed into chunks of CHUNK_BYTES
(~400 B a ring64 state, not the ~880 B of a `Received` and its strings).  The chunks come
from the C heap, not Python's small-object arenas, so a worked-off backlog's memory can be
handed back to the system (deploy.procs.forked.trim_heap) instead of staying resident.

A backlog beyond `max_bytes` loses its oldest samples of the key that overflowed it, as a
full ring would, and counts them (`dropped`): the run's report then shows them missing.
"""

from __future__ import annotations

import math
import struct
from collections import deque
from collections.abc import Iterable

from transport.bus import Received
from transport.fastbuild import build

# recv_stamp_s, hlc_stamp_s, arrival_s (NaN for None), then the lengths of key, hlc_source
# (all ones for None) and payload: 32 bits each, a key of any length a rogue may send.
_HEAD = struct.Struct("<dddIII")
_NONE_SOURCE = 0xFFFFFFFF
CHUNK_BYTES = 64 * 1024
DEFAULT_MAX_BYTES = 96 * 1024 * 1024


def _pack(item: Received) -> bytes:
    key = item.key.encode()
    source = b"" if item.hlc_source is None else item.hlc_source.encode()
    head = _HEAD.pack(item.recv_stamp_s,
                      math.nan if item.hlc_stamp_s is None else item.hlc_stamp_s,
                      math.nan if item.arrival_s is None else item.arrival_s,
                      len(key), _NONE_SOURCE if item.hlc_source is None else len(source),
                      len(item.payload))
    return b"".join((head, key, source, item.payload))


def _unpack(chunk: bytearray, at: int) -> tuple[Received, int]:
    """The entry at offset `at` of `chunk`, and the offset of the next one."""
    recv_s, hlc_s, arrival_s, n_key, n_source, n_payload = _HEAD.unpack_from(chunk, at)
    at += _HEAD.size
    key = chunk[at:at + n_key].decode()
    at += n_key
    source = None
    if n_source != _NONE_SOURCE:
        source = chunk[at:at + n_source].decode()
        at += n_source
    payload = bytes(chunk[at:at + n_payload])
    return build(Received, {
        "key": key, "payload": payload, "recv_stamp_s": recv_s,
        "hlc_stamp_s": None if hlc_s != hlc_s else hlc_s, "hlc_source": source,
        "arrival_s": None if arrival_s != arrival_s else arrival_s,
    }), at + n_payload


class _Queue:
    """One key's FIFO: sealed chunks, the one being filled, a read offset into the first."""

    def __init__(self) -> None:
        self.chunks: deque[bytearray] = deque()
        self.counts: deque[int] = deque()  # entries per chunk, for dropping whole chunks
        self.read_at = 0
        self.read_count = 0
        self.entries = 0

    def push(self, entry: bytes) -> int:
        """Append; the bytes newly allocated (a new chunk's) or 0."""
        grown = 0
        if not self.chunks or len(self.chunks[-1]) + len(entry) > CHUNK_BYTES:
            self.chunks.append(bytearray())
            self.counts.append(0)
            grown = max(CHUNK_BYTES, len(entry))
        self.chunks[-1] += entry
        self.counts[-1] += 1
        self.entries += 1
        return grown

    def pop(self) -> tuple[Received, int]:
        """The oldest entry, and the bytes freed (a used-up chunk's) or 0."""
        chunk = self.chunks[0]
        item, self.read_at = _unpack(chunk, self.read_at)
        self.read_count += 1
        self.entries -= 1
        if self.read_count < self.counts[0]:
            return item, 0
        return item, self.drop_first()

    def drop_first(self) -> int:
        """Drop the oldest chunk whole (read or not); the bytes freed."""
        chunk, count = self.chunks.popleft(), self.counts.popleft()
        self.entries -= count - self.read_count
        self.read_at = self.read_count = 0
        return max(CHUNK_BYTES, len(chunk))


class Backlog:
    """Per subscription (by its key expression), a FIFO of drained samples."""

    def __init__(self, key_exprs: Iterable[str], max_bytes: int = DEFAULT_MAX_BYTES) -> None:
        if max_bytes < 2 * CHUNK_BYTES:
            raise ValueError(f"max_bytes must be at least {2 * CHUNK_BYTES}, got {max_bytes}")
        self.max_bytes = max_bytes
        self._queues = {k: _Queue() for k in key_exprs}
        self.bytes = 0  # chunks allocated
        self.peak_bytes = 0
        self.dropped = 0

    def __len__(self) -> int:
        return sum(q.entries for q in self._queues.values())

    def take_in(self, key_expr: str, items: list[Received]) -> None:
        """Queue `items` (drained from `key_expr`'s subscription), oldest first."""
        queue = self._queues[key_expr]
        for item in items:
            self.bytes += queue.push(_pack(item))
        while self.bytes > self.max_bytes and len(queue.chunks) > 1:
            before = queue.entries
            self.bytes -= queue.drop_first()
            self.dropped += before - queue.entries
        self.peak_bytes = max(self.peak_bytes, self.bytes)

    def batch(self, per_key: int) -> list[Received]:
        """Up to `per_key` of each key's oldest samples, key after key (no key waits behind
        another's backlog)."""
        out: list[Received] = []
        for queue in self._queues.values():
            for _ in range(min(per_key, queue.entries)):
                item, freed = queue.pop()
                self.bytes -= freed
                out.append(item)
        return out
