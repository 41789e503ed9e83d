"""The recorder's fast MCAP message path writes the mcap library's bytes exactly."""

from __future__ import annotations

import io
import random
import tempfile

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from deploy.recording.mcap_fast import MessageAppender, spill_chunk_indices

Row = tuple[int, int, bytes, int, int]  # channel, log time, data, publish time, sequence


def _write(rows: list[Row], fast: bool, chunk_size: int,
           compression: CompressionType = CompressionType.NONE, spill: bool = False) -> bytes:
    out = io.BytesIO()
    writer = Writer(out, chunk_size=chunk_size, compression=compression)
    if spill:
        assert spill_chunk_indices(writer, tempfile.TemporaryFile()) is not None  # noqa: SIM115
    writer.start(profile="", library="test")
    schema = writer.register_schema("s", "jsonschema", b"{}")
    channels = [writer.register_channel(f"k/{i}", "json", schema) for i in range(3)]
    appender = MessageAppender.attach(writer) if fast else None
    for k, (channel, log_time, data, publish_time, sequence) in enumerate(rows):
        # The live view's frames still take the library's path: mixing both must hold.
        add = writer.add_message if appender is None or k % 7 == 3 else appender.add
        add(channel_id=channels[channel], log_time=log_time, data=data,
            publish_time=publish_time, sequence=sequence)
    writer.finish()
    return out.getvalue()


rows_strategy = st.lists(
    st.tuples(st.integers(0, 2), st.integers(0, 2**63 - 1), st.binary(max_size=300),
              st.integers(0, 2**63 - 1), st.integers(0, 2**32 - 1)),
    max_size=200,
)


@settings(max_examples=60, deadline=None)
@given(rows=rows_strategy, chunk_size=st.sampled_from([64, 1024, 64 * 1024]))
@pytest.mark.timeout(120)
def test_fast_appender_writes_the_same_file(rows: list[Row], chunk_size: int) -> None:
    assert _write(rows, True, chunk_size) == _write(rows, False, chunk_size)


@pytest.mark.timeout(60)
def test_same_bytes_compressed_and_readable_in_order() -> None:
    rng = random.Random(7)
    t = 1_700_000_000_000_000_000
    rows = [(rng.randrange(3), t + rng.randrange(-10**6, 10**9), rng.randbytes(rng.randrange(90)),
             t, k) for k in range(3000)]
    for compression in (CompressionType.NONE, CompressionType.LZ4):
        data = _write(rows, True, 4096, compression)
        assert data == _write(rows, False, 4096, compression)
    reader = make_reader(io.BytesIO(data))
    read = [(m.log_time, m.data, m.sequence)
            for _, _, m in reader.iter_messages(log_time_order=False)]
    assert read == [(r[1], r[2], r[4]) for r in rows]
    assert reader.get_summary().statistics.message_count == len(rows)


def test_unchunked_writer_keeps_the_library_path() -> None:
    writer = Writer(io.BytesIO(), use_chunking=False)
    writer.start(profile="", library="test")
    assert MessageAppender.attach(writer) is None


@pytest.mark.timeout(60)
def test_chunk_indexes_kept_on_disk_give_the_same_file() -> None:
    rng = random.Random(3)
    rows = [(rng.randrange(3), 10**9 + k, rng.randbytes(rng.randrange(200)), k, k)
            for k in range(2000)]
    data = _write(rows, True, 512, spill=True)
    assert data == _write(rows, True, 512)
    summary = make_reader(io.BytesIO(data)).get_summary()
    assert summary is not None and len(summary.chunk_indexes) > 100
    assert [m.sequence for _, _, m in make_reader(io.BytesIO(data)).iter_messages()] == list(
        range(2000))
