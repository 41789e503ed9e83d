"""A restarted recorder carries on the run's outputs from what its predecessor recorded.

The launcher keeps a dead recorder's MCAP beside the run as `recording-part<k>.mcap`
(deploy.launch.launcher).  Its complete chunks are readable even though the file was never
finished (mcap_log flushes each second); the new recorder reads the newest part back into
its own recording and its assembler, so that `recording.mcap`, `series.csv` and the metrics
cover the whole run but for the seconds the recorder was down.  Since every recorder copies
its predecessor, the newest part holds all earlier ones.
"""

from __future__ import annotations

import json
import logging
import re
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import msgpack
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader

from deploy.recording.mcap_log import RawFrame, RawSchema, schema_name
from errors import CodecError
from transport.codec import CODEC_VERSION, SCHEMAS, decode
from transport.messages import Message as BusMessage

log = logging.getLogger(__name__)
_PART = re.compile(r"recording-part(\d+)\.mcap$")
_CLASSES = {schema_name(cls): cls for cls in SCHEMAS}


@dataclass(frozen=True)
class Recorded:
    """One message read back: its key, the message and when the recorder received it."""

    key: str
    message: BusMessage
    recv_stamp_s: float


def newest_part(run_dir: Path) -> Path | None:
    """The MCAP the last dead recorder left (highest part number), if any."""
    parts = [(int(m.group(1)), p) for p in run_dir.glob("recording-part*.mcap")
             if (m := _PART.search(p.name)) is not None]
    return max(parts)[1] if parts else None


def message_from_json(cls: type, data: bytes) -> BusMessage:
    """The message a channel's JSON describes, checked by the codec as if it came off the
    bus (CodecError, KeyError or ValueError when it does not describe one)."""
    body = json.loads(data)
    header = body["header"]
    tag, fields = SCHEMAS[cls]
    wire = [CODEC_VERSION, tag, header["sender_id"], header["seq"], header["stamp_s"],
            *(body[f.name] for f in fields)]
    return decode(bytes(msgpack.packb(wire, use_bin_type=True)))


def read_back(path: Path, skipped: Counter[str]) -> Iterator[Recorded | RawFrame]:
    """Every message of a (possibly unfinished) recording, in file order: bus messages as
    `Recorded`, the live view's frames (channels of other schemas) as `RawFrame`s, bytes
    untouched.  What cannot be read back is counted in `skipped` by reason, and a truncated
    tail ends the reading."""
    channels: dict[int, tuple[str, type | RawSchema | None]] = {}
    schemas: dict[int, Schema] = {}
    with path.open("rb") as stream:
        try:
            for record in StreamReader(stream).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = (record.topic, _kind(record, schemas))
                elif isinstance(record, Message):
                    item = _recorded(record, channels, skipped)
                    if item is not None:
                        yield item
        except Exception as exc:  # a cut file ends in any record, in any way
            skipped["truncated_tail"] += 1
            log.debug("%s ends early: %s", path, exc)


def _kind(channel: Channel, schemas: dict[int, Schema]) -> type | RawSchema | None:
    """The bus message class of a channel, or the raw schema of a live-view channel."""
    schema = schemas.get(channel.schema_id)
    if schema is None:
        return None
    cls = _CLASSES.get(schema.name)
    if cls is not None:
        return cls
    return RawSchema(schema.name, schema.encoding, bytes(schema.data), channel.message_encoding)


def _recorded(record: Message, channels: dict[int, tuple[str, type | RawSchema | None]],
              skipped: Counter[str]) -> Recorded | RawFrame | None:
    topic, cls = channels.get(record.channel_id, ("", None))
    if isinstance(cls, RawSchema):
        return RawFrame(topic, cls, bytes(record.data), record.log_time)
    if cls is None:
        skipped["unknown_channel"] += 1
        return None
    try:
        msg = message_from_json(cls, record.data)
    except (CodecError, KeyError, ValueError, TypeError):
        skipped["unreadable"] += 1
        return None
    return Recorded(topic, msg, record.log_time * 1e-9)
