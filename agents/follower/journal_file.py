"""A follower's input journal on disk: frames of msgpack records, each frame checked.

The file is a header frame, then data frames.  A frame is `<u32 length><u32 crc32>`
and `length` bytes: the header's msgpack map, or a data frame's msgpack records one after
another, zlib-compressed (level 1: a second of a follower's records shrinks by about 40 %
for ~0.1 % of its CPU; raw, the paper case's journal was over 1 MB a minute); the writer
gathers records
and writes one frame a second (`FLUSH_EVERY_S`) with a single unbuffered write, so
what was flushed survives a SIGKILL: a reader stops at the last whole frame and says
where (`Frames.stopped`).  A frame whose CRC does not match is a damaged record,
named by file and offset (JournalError); so is a header of another journal version.
Nothing here knows what the records mean (agents.follower.journal does).
"""

from __future__ import annotations

import os
import struct
import time
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack

from enclose_release import VERSION
from errors import JournalError

JOURNAL_VERSION = 1


ZLIB_LEVEL = 1
MAGIC = "enclose-journal"
FLUSH_EVERY_S = 1.0
_FRAME = struct.Struct("<II")
# A frame longer than this is a damaged length, not a second of records.
MAX_FRAME_BYTES = 64 << 20


class FrameWriter:
    """Appends records to `path`; `header` is written first, flushed at once."""

    def __init__(self, path: Path, header: dict[str, Any]) -> None:
        self.path = path
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._pack = msgpack.Packer(use_bin_type=True).pack
        self._parts: list[bytes] = []
        self._next_flush_s = time.monotonic() + FLUSH_EVERY_S
        self.bytes_written = 0
        self._write(self._pack({"magic": MAGIC, "version": JOURNAL_VERSION,
                                "enclose": VERSION, **header}))

    def add(self, record: object) -> None:
        self._parts.append(self._pack(record))
        if time.monotonic() >= self._next_flush_s:
            self.flush()

    def flush(self) -> None:
        self._next_flush_s = time.monotonic() + FLUSH_EVERY_S
        if self._parts:
            data, self._parts = b"".join(self._parts), []
            self._write(zlib.compress(data, ZLIB_LEVEL))

    def _write(self, data: bytes) -> None:
        frame = _FRAME.pack(len(data), zlib.crc32(data)) + data
        os.write(self._fd, frame)
        self.bytes_written += len(frame)

    def close(self) -> None:
        try:
            self.flush()
        finally:
            os.close(self._fd)


@dataclass
class Frames:
    """The records of one journal file, read lazily; `header` is read on opening."""

    path: Path
    header: dict[str, Any]
    _data: bytes
    _offset: int
    stopped: str | None = None  # where and why reading stopped before the file's end

    @classmethod
    def open(cls, path: Path) -> Frames:
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise JournalError(str(path), 0, f"cannot read: {exc.strerror}") from None
        frames = cls(path, {}, data, 0)
        first = frames._frame()
        if first is None:
            raise JournalError(str(path), 0, "no header (an empty or cut journal)")
        try:
            header = msgpack.unpackb(first, raw=False, strict_map_key=False)
        except Exception as exc:
            raise JournalError(str(path), 0, f"unreadable header: {exc}") from None
        if not isinstance(header, dict) or header.get("magic") != MAGIC:
            raise JournalError(str(path), 0, "not an enclose journal")
        mine = VERSION  # a replay by another release need not reproduce: it is refused
        if header.get("version") != JOURNAL_VERSION or header.get("enclose") != mine:
            raise JournalError(
                str(path), 0, f"written by enclose {header.get('enclose')!r} (journal "
                f"version {header.get('version')!r}), this is enclose {mine!r} (journal "
                f"version {JOURNAL_VERSION}): replay it with the enclose that ran it")
        frames.header = header
        return frames

    def _frame(self) -> bytes | None:
        """The next whole frame's payload; None at the end or at a cut tail."""
        data, at = self._data, self._offset
        if at == len(data):
            return None
        if at + _FRAME.size > len(data):
            self.stopped = f"a frame cut short at byte {at} (the process was killed)"
            return None
        length, crc = _FRAME.unpack_from(data, at)
        end = at + _FRAME.size + length
        if length > MAX_FRAME_BYTES:
            raise JournalError(str(self.path), at, f"damaged frame length {length}")
        if end > len(data):
            self.stopped = f"a frame cut short at byte {at} (the process was killed)"
            return None
        payload = data[at + _FRAME.size:end]
        if zlib.crc32(payload) != crc:
            raise JournalError(str(self.path), at, "damaged frame (CRC mismatch)")
        self._offset = end
        return payload

    def records(self) -> Iterator[tuple[int, Any]]:
        """(offset of its frame, record) for every record of every whole frame."""
        while True:
            at = self._offset
            payload = self._frame()
            if payload is None:
                return
            unpacker = msgpack.Unpacker(raw=False, strict_map_key=False)
            try:
                unpacker.feed(zlib.decompress(payload))
                for record in unpacker:
                    yield at, record
            except Exception as exc:
                raise JournalError(str(self.path), at, f"damaged record: {exc}") from None
