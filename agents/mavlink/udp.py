"""The adapter's UDP socket: bound, non-blocking, with kernel receive stamps where it can."""

from __future__ import annotations

import contextlib
import socket

from agents.mavlink.timemap import SO_TIMESTAMPNS
from transport.errors import MavlinkError


def bind_udp(host: str, port: int) -> socket.socket:
    """A non-blocking UDP socket bound to host:port; MavlinkError names the address when
    it cannot be bound.  Kernel receive stamps (SO_TIMESTAMPNS) are asked for: a datagram
    that waited in the buffer is then stamped with its arrival, not with when it was read
    (agents.mavlink.timemap.kernel_arrival_s); without them the read time stands in."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise MavlinkError(f"cannot bind {host}:{port}: {exc.strerror}") from exc
    sock.setblocking(False)
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    return sock
