"""The adapter's UDP socket: bound, non-blocking, with kernel receive stamps where it can."""

from __future__ import annotations

import contextlib
import socket
import struct

from agents.mavlink.timemap import SO_TIMESTAMPNS
from errors import MavlinkError

SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)  # Linux; Python does not export it
_U32 = struct.Struct("I")
# recvmsg's room for both ancillary items: a timespec and a drop count.
ANCILLARY_BYTES = socket.CMSG_SPACE(16) + socket.CMSG_SPACE(4)


def bind_udp(host: str, port: int, peer: tuple[str, int] | None = None) -> socket.socket:
    """A non-blocking UDP socket bound to host:port, connected to `peer` if given (the
    kernel then drops every other sender's datagram unread); MavlinkError names the address
    when it cannot be bound or connected.  Kernel receive stamps (SO_TIMESTAMPNS) are
    asked for: a datagram that waited in the buffer is then stamped with its arrival, not
    with when it was read (agents.mavlink.timemap.kernel_arrival_s); without them the read
    time stands in.  So is
    the kernel's count of datagrams it dropped on a full buffer (SO_RXQ_OVFL, `kernel_drops`):
    a flood the receiver does not read to the end still shows."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((host, port))
        if peer is not None:
            sock.connect(peer)
    except OSError as exc:
        sock.close()
        where = f"{host}:{port}" if peer is None else f"{host}:{port} to {peer[0]}:{peer[1]}"
        raise MavlinkError(f"cannot bind {where}: {exc.strerror}") from exc
    sock.setblocking(False)
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
    return sock


def kernel_drops(ancillary: list[tuple[int, int, bytes]]) -> int | None:
    """The socket's count of datagrams the kernel dropped so far, if the datagram carried it
    (the kernel adds it only once there was a drop)."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(data) >= 4:
            return int(_U32.unpack_from(data)[0])
    return None
