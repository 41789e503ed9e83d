"""The live view's WebSocket server (foxglove-sdk): the recorder's frames, as they come.

Clients speak the Foxglove WebSocket protocol (subprotocol `foxglove.sdk.v1`): Foxglove's
"Open connection" -> "Foxglove WebSocket" -> the URL.  The server binds `host` (127.0.0.1 by
default: the view has no authentication, unlike the Zenoh side with its mTLS and ACL, so it
is not offered beyond this machine unless asked for) on `port`, or the next free port of the
`PORT_TRIES` after it.  Channels are advertised as their first frame comes; a channel's
frames are encoded once (`deploy.recording.view`) and go both here and into the MCAP.
"""

from __future__ import annotations

import ipaddress
import logging

import foxglove

from deploy.recording.live_defaults import DEFAULT_HOST, DEFAULT_PORT
from deploy.recording.view import ViewFrame
from errors import DeployError

log = logging.getLogger(__name__)
PORT_TRIES = 20
SERVER_NAME = "enclose"
SUBPROTOCOL = "foxglove.sdk.v1"


def is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


class LiveServer:
    """A running server and its channels; `stop()` closes it (always call it)."""

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 tries: int = PORT_TRIES) -> None:
        if not 0 <= port <= 65535:
            raise DeployError(f"live port {port} is not a TCP port (0..65535)")
        if not is_loopback(host):
            log.warning("live view on %s: anyone who can reach this address can watch the run "
                        "(the live view has no authentication)", host)
        self.context = foxglove.Context()  # own context: nothing else logs into it
        self.server = self._bind(host, port, 1 if port == 0 else tries)
        self.host = host
        self.port = int(self.server.port)
        self._channels: dict[str, foxglove.Channel] = {}
        self.frames_sent = 0

    def _bind(self, host: str, port: int, tries: int) -> foxglove.WebSocketServer:
        error: Exception | None = None
        for candidate in range(port, min(port + tries, 65536)):
            try:
                return foxglove.start_server(name=SERVER_NAME, host=host, port=candidate,
                                             context=self.context)
            except RuntimeError as exc:  # FoxgloveError: address in use, or not bindable
                error = exc
        raise DeployError(f"live view: no free port in {port}..{port + tries - 1} on {host} "
                          f"({error})")

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    def publish(self, frame: ViewFrame) -> None:
        channel = self._channels.get(frame.topic)
        if channel is None:
            s = frame.schema
            channel = foxglove.Channel(
                frame.topic, schema=foxglove.Schema(name=s.name, encoding=s.encoding, data=s.data),
                message_encoding=s.message_encoding, context=self.context)
            self._channels[frame.topic] = channel
        channel.log(frame.data, log_time=frame.log_time_ns)
        self.frames_sent += 1

    def stop(self) -> None:
        for channel in self._channels.values():
            channel.close()
        self.server.stop()
