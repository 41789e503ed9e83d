"""A Foxglove WebSocket protocol client for tests, on `websockets` and `protobuf` from PyPI.

It speaks what Foxglove's app speaks (github.com/foxglove/ws-protocol docs/spec.md, with the
SDK server's subprotocol `foxglove.sdk.v1`): JSON text ops `serverInfo` and `advertise` from
the server, `subscribe` from the client, and binary "message data" frames (opcode 0x01,
uint32 subscription id, uint64 log time in ns, payload; little-endian).  Protobuf payloads
are decoded with the schema the server advertised (a base64 FileDescriptorSet), as the app
does -- nothing of the project's own code is used.
"""

from __future__ import annotations

import base64
import contextlib
import json
import struct
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from websockets.sync.client import ClientConnection, connect

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01
_HEADER = struct.Struct("<BIQ")


@dataclass(frozen=True)
class Received:
    topic: str
    log_time_ns: int
    payload: bytes


@contextlib.contextmanager
def foxglove_client(url: str, open_timeout_s: float = 10.0) -> Iterator[FoxgloveClient]:
    with connect(url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                 open_timeout=open_timeout_s, max_size=None) as ws:
        yield FoxgloveClient(ws)


class FoxgloveClient:
    """One connection; channels as advertised, by topic."""

    def __init__(self, ws: ClientConnection) -> None:
        self.ws = ws
        self.server_info: dict[str, Any] = {}
        self.channels: dict[str, dict[str, Any]] = {}
        self._subs: dict[int, str] = {}

    def _handle_text(self, text: str) -> None:
        op = json.loads(text)
        if op.get("op") == "serverInfo":
            self.server_info = op
        elif op.get("op") == "advertise":
            self.channels.update({c["topic"]: c for c in op["channels"]})
        elif op.get("op") == "unadvertise":
            gone = set(op["channelIds"])
            self.channels = {t: c for t, c in self.channels.items() if c["id"] not in gone}

    def _pump(self, deadline: float) -> Received | None:
        frame = self.ws.recv(timeout=max(0.0, deadline - time.monotonic()))
        if isinstance(frame, str):
            self._handle_text(frame)
            return None
        op, sub, log_time = _HEADER.unpack_from(frame)
        if op != MESSAGE_DATA or sub not in self._subs:
            return None
        return Received(self._subs[sub], log_time, bytes(frame[_HEADER.size:]))

    def wait_channels(self, topics: set[str], timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while not topics <= set(self.channels):
            if time.monotonic() > deadline:
                raise AssertionError(f"channels {sorted(topics - set(self.channels))} not "
                                     f"advertised in {timeout_s} s (got {sorted(self.channels)})")
            self._pump(deadline)

    def subscribe(self, topics: list[str]) -> None:
        subs = []
        for topic in topics:
            sub_id = len(self._subs) + 1
            self._subs[sub_id] = topic
            subs.append({"id": sub_id, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def receive(self, count: int, timeout_s: float) -> list[Received]:
        """`count` messages of the subscribed channels (fewer if the time runs out)."""
        deadline = time.monotonic() + timeout_s
        out: list[Received] = []
        while len(out) < count and time.monotonic() < deadline:
            try:
                item = self._pump(deadline)
            except TimeoutError:
                break
            if item is not None:
                out.append(item)
        return out

    def protobuf_class(self, topic: str) -> Any:
        """The message class the advertised protobuf schema of `topic` describes."""
        channel = self.channels[topic]
        assert channel["encoding"] == "protobuf" and channel["schemaEncoding"] == "protobuf"
        return protobuf_class(channel["schemaName"], base64.b64decode(channel["schema"]))


def protobuf_class(name: str, file_descriptor_set: bytes) -> Any:
    """The class of message `name` from a serialised FileDescriptorSet (MCAP's and the
    protocol's protobuf schema data)."""
    files = descriptor_pb2.FileDescriptorSet.FromString(file_descriptor_set)
    pool = descriptor_pool.DescriptorPool()
    for proto in files.file:
        pool.Add(proto)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))
