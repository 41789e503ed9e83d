"""A fast twin of `mcap.writer.Writer.add_message` for chunked files.

The mcap library builds each Message record with six small writes and a seek back for its
length: at n = 16 the recorder writes ~1 700 messages a second and that was a third of its
CPU (issue 15).  `MessageAppender.add` does the same bookkeeping (statistics, the chunk's
message index, the chunk's size check) and packs the record with one `struct.pack`.  It
reaches into the Writer's private state, so it is used only where that state looks as
expected (`MessageAppender.attach` returns None otherwise, and the caller keeps the
library's path); tests/unit/test_mcap_fast.py pins the file to the library's byte for byte.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

from mcap.opcode import Opcode
from mcap.records import MessageIndex
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
