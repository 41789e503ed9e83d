"""A restarted recorder carries on the run's outputs from what its predecessor recorded.

The launcher keeps a dead recorder's MCAP beside the run as `recording-part<k>.mcap`
(deploy.launch.launcher).  Its complete chunks are readable even though the file was never
finished (mcap_log flushes each second); the new recorder reads the newest part back into
its own recording and its assembler, so that `recording.mcap`, `series.csv` and the metrics
cover the whole run but for the seconds the recorder was down.  Since every recorder copies
its predecessor, the newest part holds all earlier ones.

`read_back` gives each bus message as its wire payload (its `json` channel's message turned
back into its wire array): the new recorder records and checks it as if it came off the bus
again.  A recording holds every follower state and observation that was a wire array of its
type, also those refused when decoded (deploy.recording.intake): `read_messages` decodes
(codec checks only, the malformed skipped and counted); the recorder's own checks (senders,
plausibility, law fields) are its `Decoder`'s.
"""

from __future__ import annotations

import json
import logging
import re
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import msgpack
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader

from deploy.recording.mcap_log import (
    MESSAGE_ENCODING,
    RawFrame,
    RawSchema,
    schema_name,
)
from errors import CodecError
from transport.bus import Received
from transport.codec import CODEC_VERSION, SCHEMAS, decode
from transport.messages import Message as BusMessage

log = logging.getLogger(__name__)
_PART = re.compile(r"recording-part(\d+)\.mcap$")
_CLASSES = {schema_name(cls): cls for cls in SCHEMAS}


@dataclass(frozen=True)
class Recorded:
    """One message read back: its key, its wire payload and when the recorder received it."""

    key: str
    payload: bytes
    recv_stamp_s: float

    @property
    def message(self) -> BusMessage:
        """The payload decoded (CodecError if it does not decode)."""
        return decode(self.payload)


def newest_part(run_dir: Path) -> Path | None:
    """The MCAP the last dead recorder left (highest part number), if any."""
    parts = [(int(m.group(1)), p) for p in run_dir.glob("recording-part*.mcap")
             if (m := _PART.search(p.name)) is not None]
    return max(parts)[1] if parts else None


def wire_from_json(cls: type, data: bytes) -> bytes:
    """The wire payload of the message an old (`json`) channel's message describes
    (KeyError, ValueError or TypeError when it describes none)."""
    body = json.loads(data)
    header = body["header"]
    tag, fields = SCHEMAS[cls]
    wire = [CODEC_VERSION, tag, header["sender_id"], header["seq"], header["stamp_s"],
            *(body[f.name] for f in fields)]
    return bytes(msgpack.packb(wire, use_bin_type=True))


def carry_on(run_dir: Path, carried: Counter[str], write_raw: Callable[[RawFrame], None],
             take: Callable[[Received], None]) -> None:
    """The newest part's live-view frames to `write_raw`, its bus messages to `take` as if
    they came off the bus again; counted in `carried` with what could not be read."""
    part = newest_part(run_dir)
    if part is None:
        return
    for item in read_back(part, carried):
        if isinstance(item, RawFrame):  # the dead one's live view, as it was
            write_raw(item)
            carried["view_frames"] += 1
        else:
            carried["messages"] += 1
            take(Received(item.key, item.payload, item.recv_stamp_s))
    log.info("carried on from %s: %s", part.name, dict(carried))


def message_from_json(cls: type, data: bytes) -> BusMessage:
    """The message a `json` channel's JSON describes, checked by the codec as if it came
    off the bus (CodecError, KeyError or ValueError when it does not describe one)."""
    return decode(wire_from_json(cls, data))


def read_messages(path: Path, skipped: Counter[str]) -> Iterator[tuple[str, BusMessage, float]]:
    """(key, message, receive stamp) of every bus message of a recording that decodes;
    what does not is counted in `skipped` ("unreadable")."""
    for item in read_back(path, skipped):
        if isinstance(item, Recorded):
            try:
                yield item.key, item.message, item.recv_stamp_s
            except CodecError:
                skipped["unreadable"] += 1


def read_back(path: Path, skipped: Counter[str]) -> Iterator[Recorded | RawFrame]:
    """Every message of a (possibly unfinished) recording, in file order: bus messages as
    `Recorded`, the live view's frames (channels of other schemas) as `RawFrame`s, bytes
    untouched.  What cannot be read back is counted in `skipped` by reason, and a truncated
    tail ends the reading."""
    channels: dict[int, tuple[str, type | RawSchema | None]] = {}
    encodings: dict[int, str] = {}
    schemas: dict[int, Schema] = {}
    with path.open("rb") as stream:
        try:
            for record in StreamReader(stream).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = (record.topic, _kind(record, schemas))
                    encodings[record.id] = record.message_encoding
                elif isinstance(record, Message):
                    item = _recorded(record, channels, encodings, skipped)
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
              encodings: dict[int, str], skipped: Counter[str]) -> Recorded | RawFrame | None:
    topic, cls = channels.get(record.channel_id, ("", None))
    if isinstance(cls, RawSchema):
        return RawFrame(topic, cls, bytes(record.data), record.log_time)
    encoding = encodings.get(record.channel_id)
    if cls is None or encoding != MESSAGE_ENCODING:
        skipped["unknown_channel"] += 1
        return None
    try:
        payload = wire_from_json(cls, record.data)
    except (KeyError, ValueError, TypeError):
        skipped["unreadable"] += 1
        return None
    return Recorded(topic, payload, record.log_time * 1e-9)
