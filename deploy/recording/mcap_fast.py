"""Where the recorder reaches into `mcap.writer.Writer`: a fast `add_message`, and chunk
indexes kept on disk.

The mcap library builds each Message record with six small writes and a seek back for its
length: at n = 16 the recorder writes ~1 700 messages a second and that was a third of its
CPU (issue 15).  `MessageAppender.add` does the same bookkeeping (statistics, the chunk's
message index, the chunk's size check) and packs the record with one `struct.pack`.  It
reaches into the Writer's private state, so it is used only where that state looks as
expected (`MessageAppender.attach` returns None otherwise, and the caller keeps the
library's path); tests/unit/test_mcap_fast.py pins the file to the library's byte for byte.

The Writer keeps one `ChunkIndex` object per chunk until `finish()` writes the summary: about
1 kB a second of recording, held for the whole run, and the run may last hours.
`spill_chunk_indices` swaps that list for `SpilledChunkIndices`, which keeps each index's
record bytes in a temporary file and hands them back at `finish()`: the same summary.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from typing import IO, Any

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import ChunkIndex, MessageIndex
from mcap.writer import Writer

# opcode, record length, channel id, sequence, log time, publish time (then the data)
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_FIXED_BYTES = _MESSAGE_HEAD.size - 9  # the record length counts what follows it


class MessageAppender:
    """Appends Message records to a chunked Writer's current chunk."""

    def __init__(self, stats: Any, chunk: Any, maybe_finalize: Callable[[], None]) -> None:
        self._stats, self._chunk, self._maybe_finalize = stats, chunk, maybe_finalize
        self._builder = chunk.record_writer

    @classmethod
    def attach(cls, writer: Writer) -> MessageAppender | None:
        """The appender for `writer`, or None if its internals are not the ones known."""
        stats = getattr(writer, "_Writer__statistics", None)
        chunk = getattr(writer, "_Writer__chunk_builder", None)
        finalize = getattr(writer, "_Writer__maybe_finalize_chunk", None)
        builder = getattr(chunk, "record_writer", None)
        known = (
            stats is not None and finalize is not None and builder is not None
            and all(hasattr(stats, a) for a in ("message_count", "message_start_time",
                                                 "message_end_time", "channel_message_counts"))
            and all(hasattr(chunk, a) for a in ("message_indices", "message_start_time",
                                                 "message_end_time", "num_messages"))
            and hasattr(builder, "_buffer")
        )
        if not known or finalize is None:
            return None
        return cls(stats, chunk, finalize)

    def add(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
            sequence: int) -> None:
        """`Writer.add_message(...)` with the same effect on the file and the summary."""
        stats, chunk = self._stats, self._chunk
        if stats.message_count == 0 or log_time < stats.message_start_time:
            stats.message_start_time = log_time
        if log_time > stats.message_end_time:
            stats.message_end_time = log_time
        stats.channel_message_counts[channel_id] += 1
        stats.message_count += 1
        if chunk.num_messages == 0 or log_time < chunk.message_start_time:
            chunk.message_start_time = log_time
        if log_time > chunk.message_end_time:
            chunk.message_end_time = log_time
        index = chunk.message_indices.get(channel_id)
        if not index:
            index = chunk.message_indices[channel_id] = MessageIndex(channel_id=channel_id,
                                                                     records=[])
        buffer = self._builder._buffer  # a new BytesIO after every chunk
        index.records.append((log_time, buffer.tell()))
        chunk.num_messages += 1
        buffer.write(_MESSAGE_HEAD.pack(Opcode.MESSAGE, _FIXED_BYTES + len(data), channel_id,
                                        sequence, log_time, publish_time) + data)
        self._maybe_finalize()


_LENGTH = struct.Struct("<I")


class _WrittenRecord:
    """A record's bytes, written again as they were (what the summary asks of an index)."""

    def __init__(self, data: bytes) -> None:
        self.data = data

    def write(self, builder: RecordBuilder) -> None:
        builder.write(self.data)


class SpilledChunkIndices:
    """The Writer's list of chunk indexes, on disk: `append` and one pass of `iter`."""

    def __init__(self, stream: IO[bytes]) -> None:
        self._stream = stream
        self._count = 0

    def append(self, index: ChunkIndex) -> None:
        builder = RecordBuilder()
        index.write(builder)
        data = builder.end()
        self._stream.write(_LENGTH.pack(len(data)) + data)
        self._count += 1

    def __len__(self) -> int:
        return self._count

    def __iter__(self) -> Iterator[_WrittenRecord]:
        self._stream.flush()
        self._stream.seek(0)
        for _ in range(self._count):
            (size,) = _LENGTH.unpack(self._stream.read(_LENGTH.size))
            yield _WrittenRecord(self._stream.read(size))
        self._stream.seek(0, 2)  # appending goes on at the end

    def close(self) -> None:
        self._stream.close()


def spill_chunk_indices(writer: Writer, stream: IO[bytes]) -> SpilledChunkIndices | None:
    """Keep `writer`'s chunk indexes in `stream` (a temporary file) instead of memory; None,
    and the library's list kept, where the Writer's internals are not the ones known."""
    current = getattr(writer, "_Writer__chunk_indices", None)
    if not isinstance(current, list) or current:
        return None
    spilled = SpilledChunkIndices(stream)
    setattr(writer, "_Writer__chunk_indices", spilled)  # noqa: B010  # a private name
    return spilled
