"""A streaming MCAP recording of the bus: one JSON channel per key, JSON schemas per type.

Foxglove and PlotJuggler read `json` messages described by `jsonschema` schemas.  The schemas
are generated from the message dataclasses, so a field added to a message shows up here
without an edit.  A message is the dataclass as an object: `write` makes it from a decoded
message, `wire_json` from a payload as it arrived, without decoding it into the dataclass
(the recorder checks follower states and observations later, in batches:
deploy.recording.intake).  log_time is the recorder's receive time, publish_time the
sender's stamp.
Messages go into compressed chunks of `chunk_size` bytes written as soon as they fill, and
the file object is flushed each `flush()`: a crash loses at most the chunk being built.
"""

from __future__ import annotations

import dataclasses
import json
import tempfile
import types
import typing
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import msgspec
from mcap.writer import CompressionType, Writer

from deploy.recording.mcap_fast import MessageAppender, spill_chunk_indices
from transport.codec import CODEC_VERSION, SCHEMAS
from transport.messages import Message

MESSAGE_ENCODING = "json"
SCHEMA_ENCODING = "jsonschema"
DEFAULT_CHUNK_BYTES = 64 * 1024
_NS = 1_000_000_000


def _compression() -> CompressionType:
    try:
        import zstandard  # noqa: F401  # only probing: mcap needs it for ZSTD
    except ImportError:
        return CompressionType.NONE
    return CompressionType.ZSTD


def _type_schema(tp: Any) -> dict[str, Any]:
    """JSON schema of one annotated field type (numbers, strings, tuples, maps, Header)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is float:
        return {"type": "number"}
    if tp is int:
        return {"type": "integer"}
    if tp is str:
        return {"type": "string"}
    if tp is bool:
        return {"type": "boolean"}
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return dataclass_schema(tp)
    if origin in (types.UnionType, typing.Union):
        inner = [a for a in args if a is not type(None)]
        if len(inner) == 1 and len(args) == 2:
            sub = _type_schema(inner[0])
            return {**sub, "type": [sub["type"], "null"]}
        return {"anyOf": [_type_schema(a) for a in args]}
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return {"type": "array", "items": _type_schema(args[0])}
        items = [_type_schema(a) for a in args]
        if all(i == items[0] for i in items):
            return {"type": "array", "items": items[0], "minItems": len(args),
                    "maxItems": len(args)}
        return {"type": "array", "prefixItems": items, "minItems": len(args),
                "maxItems": len(args)}
    if origin in (Mapping, dict) or tp is dict:
        value = _type_schema(args[1]) if args else {}
        return {"type": "object", "additionalProperties": value}
    raise TypeError(f"no JSON schema for field type {tp!r}")


def dataclass_schema(cls: type) -> dict[str, Any]:
    """JSON schema (object) of a message dataclass, from its type-annotated fields."""
    hints = typing.get_type_hints(cls)
    fields = dataclasses.fields(cls)
    return {
        "type": "object",
        "title": cls.__name__,
        "properties": {f.name: _type_schema(hints[f.name]) for f in fields},
        "required": [f.name for f in fields],
    }


_FIELD_NAMES: dict[type, tuple[str, ...]] = {}


def _mapping_as_dict(obj: object) -> dict[str, Any]:
    """Counters arrive as mappings that are not dicts (e.g. a Counter subclass)."""
    if isinstance(obj, Mapping):
        return dict(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


# The same bytes as json.dumps(separators=(",", ":")) at a sixth of its cost: at n = 16 the
# recorder writes ~1 700 messages a second, and json was a fifth of its CPU.
_JSON = msgspec.json.Encoder(enc_hook=_mapping_as_dict)


_UNPACK = msgspec.msgpack.Decoder()
_WIRE_NAMES: dict[tuple[type, int], tuple[int, tuple[str, ...]]] = {}


def _wire_names(cls: type, version: int) -> tuple[int, tuple[str, ...]]:
    """(type tag, the names of its fields a payload of codec `version` carries)."""
    names = _WIRE_NAMES.get((cls, version))
    if names is None:
        tag, fields = SCHEMAS[cls]
        names = _WIRE_NAMES[(cls, version)] = (
            tag, tuple(f.name for f in fields if f.since <= version))
    return names


def wire_json(cls: type, payload: bytes) -> tuple[bytes, int, int] | None:
    """(the JSON `message_json` gives the message in `payload`, its sender's stamp in ns, its
    sequence number), made from the codec's wire array without the dataclass; None if
    `payload` is no wire array of `cls` of this codec version (the decoder refuses it)."""
    try:
        wire = _UNPACK.decode(payload)
        version, tag, sid, seq, stamp_s = wire[:5]
        # Types first: a hostile list or string as the stamp times 1e9 is a gigabyte.
        if type(version) is not int or version != CODEC_VERSION or type(seq) is not int \
                or type(stamp_s) is not float or stamp_s - stamp_s != 0.0:
            return None
        want, names = _wire_names(cls, version)
        if tag != want or len(wire) != 5 + len(names):
            return None
        body = {"header": {"sender_id": sid, "seq": seq, "stamp_s": stamp_s},
                **dict(zip(names, wire[5:], strict=True))}
        data = _JSON.encode(body)
        stamp_ns = int(stamp_s * _NS)
    except Exception:  # hostile input: the decoder and encoder raise many types (deep nesting:
        return None    # RecursionError), as the codec's unpacking does
    return data, max(0, stamp_ns), seq & 0xFFFFFFFF


def message_json(msg: Message) -> bytes:
    """The JSON a channel carries: the dataclass as an object, vectors as arrays.

    Equal to `json.dumps(dataclasses.asdict(msg))`, at a fraction of its cost (asdict
    deep-copies every tuple): messages are flat but for the header.  msgspec encodes a
    dataclass itself, in field order, at half the cost again (~1.3 of 2.6 µs): a type takes
    that path once its first message came out the same both ways (`_DIRECT`).
    """
    direct = _DIRECT.get(type(msg))
    if direct:
        try:
            return _JSON.encode(msg)
        except (TypeError, ValueError):
            return _dict_json(msg)
    data = _dict_json(msg)
    if direct is None:
        try:
            _DIRECT[type(msg)] = _JSON.encode(msg) == data
        except (TypeError, ValueError):
            _DIRECT[type(msg)] = False
    return data


_DIRECT: dict[type, bool] = {}  # per message type: msgspec's own dataclass encoding agrees


def _dict_json(msg: Message) -> bytes:
    names = _FIELD_NAMES.get(type(msg))
    if names is None:
        names = _FIELD_NAMES[type(msg)] = tuple(f.name for f in dataclasses.fields(msg))
    h = msg.header
    body: dict[str, Any] = {"header": {"sender_id": h.sender_id, "seq": h.seq,
                                       "stamp_s": h.stamp_s}}
    body.update((name, getattr(msg, name)) for name in names if name != "header")
    try:
        return _JSON.encode(body)
    except (TypeError, ValueError):  # not what msgspec knows: the standard encoder says why
        return json.dumps(body, separators=(",", ":"), default=_mapping_as_dict).encode()


@dataclass(frozen=True)
class RawSchema:
    """A channel schema given as bytes (the live view's, e.g. foxglove.SceneUpdate)."""

    name: str
    encoding: str  # schema encoding: "protobuf" | "jsonschema"
    data: bytes
    message_encoding: str  # "protobuf" | "json"


@dataclass(frozen=True)
class RawFrame:
    """An already encoded message of a `RawSchema` channel."""

    topic: str
    schema: RawSchema
    data: bytes
    log_time_ns: int


def schema_name(cls: type) -> str:
    return f"enclose.{cls.__name__}"


class McapLog:
    """Incremental MCAP writer; `close()` writes the summary (always call it, e.g. in finally)."""

    def __init__(self, path: Path, chunk_size: int = DEFAULT_CHUNK_BYTES,
                 metadata: Mapping[str, str] | None = None) -> None:
        self.path = path
        self.messages: Counter[str] = Counter()  # per key
        self.frames: Counter[str] = Counter()  # live-view frames, per topic
        self._stream: IO[bytes] = open(path, "wb")  # noqa: SIM115  # closed in close()
        self._writer = Writer(self._stream, chunk_size=chunk_size, compression=_compression())
        self._writer.start(profile="", library="enclose-recorder")
        self._fast = MessageAppender.attach(self._writer)  # None: the library's own path
        # Chunk indexes on disk until the summary: memory flat over hours (mcap_fast).
        spool = tempfile.TemporaryFile(dir=path.parent)  # noqa: SIM115  # closed in close()
        self._indices = spill_chunk_indices(self._writer, spool)
        if self._indices is None:
            spool.close()
        self._schemas: dict[type, int] = {}
        self._channels: dict[str, int] = {}
        self._raw_schemas: dict[RawSchema, int] = {}
        self.closed = False
        if metadata:
            self._writer.add_metadata("enclose", dict(metadata))

    def channel(self, key: str, cls: type) -> int:
        """The `json` channel of `key` (registered at its first use)."""
        channel = self._channels.get(key)
        if channel is None:
            schema = self._schemas.get(cls)
            if schema is None:
                data = json.dumps(dataclass_schema(cls)).encode()
                schema = self._writer.register_schema(schema_name(cls), SCHEMA_ENCODING, data)
                self._schemas[cls] = schema
            channel = self._writer.register_channel(key, MESSAGE_ENCODING, schema)
            self._channels[key] = channel
        return channel

    def write(self, key: str, msg: Message, recv_stamp_s: float) -> None:
        channel = self.channel(key, type(msg))
        add = self._writer.add_message if self._fast is None else self._fast.add
        add(channel_id=channel, log_time=int(recv_stamp_s * _NS), data=message_json(msg),
            publish_time=max(0, int(msg.header.stamp_s * _NS)),
            sequence=msg.header.seq & 0xFFFFFFFF)
        self.messages[key] += 1

    def write_json(self, key: str, channel: int, data: bytes, log_time_ns: int,
                   publish_time_ns: int | None = None, sequence: int = 0) -> None:
        """A message's JSON (`wire_json`) on `key`'s `channel`."""
        add = self._writer.add_message if self._fast is None else self._fast.add
        add(channel_id=channel, log_time=log_time_ns, data=data,
            publish_time=log_time_ns if publish_time_ns is None else publish_time_ns,
            sequence=sequence)
        self.messages[key] += 1

    def write_raw(self, frame: RawFrame) -> None:
        """A message already encoded (the live view's frames: same bytes as live)."""
        channel = self._channels.get(frame.topic)
        if channel is None:
            s = frame.schema
            schema = self._raw_schemas.get(s)
            if schema is None:
                schema = self._writer.register_schema(s.name, s.encoding, s.data)
                self._raw_schemas[s] = schema
            channel = self._writer.register_channel(frame.topic, s.message_encoding, schema)
            self._channels[frame.topic] = channel
        self._writer.add_message(channel_id=channel, log_time=frame.log_time_ns,
                                 data=frame.data, publish_time=frame.log_time_ns)
        self.frames[frame.topic] += 1

    def flush(self) -> None:
        """Push finished chunks to the OS, so they survive a crash of this process."""
        if not self.closed:
            self._stream.flush()

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        try:
            self._writer.finish()
        finally:
            self._stream.close()
            if self._indices is not None:
                self._indices.close()

