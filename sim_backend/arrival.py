"""How long a datagram waited in a vehicle's socket, from the kernel's receive stamp.

The simulator reads its sockets once a tick (sim_backend.runtime): a datagram may wait up
to a tick in its socket buffer before it is handled.  Most messages do not mind, but a
TIMESYNC request answered with the clock at handling time would put that wait on the
request's leg of the round trip alone, and the client's offset (the round trip's
midpoint) would be off by half of it, the same every time for an agent that ticks in
step with the simulator.  So each socket asks the kernel to stamp arrivals
(SO_TIMESTAMPNS), read as the agents' adapter reads them
(agents.mavlink.timemap.kernel_arrival_s), and sim_backend.clock_services answers with the
midpoint between arrival and reply.  Where the option is missing (not Linux), nothing is
stamped and the wait counts as 0.
"""

from __future__ import annotations

import socket

from agents.mavlink.timemap import SO_TIMESTAMPNS, kernel_arrival_s

ANCILLARY_BYTES = socket.CMSG_SPACE(16)  # one struct timespec: two int64
MAX_HELD_S = 1.0  # a longer "wait" is a clock step or a foreign stamp: counted as none
Ancillary = list[tuple[int, int, bytes]]


def stamp_arrivals(sock: socket.socket) -> bool:
    """Ask the kernel to stamp each datagram of `sock`; False where it cannot."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


def held_s(ancillary: Ancillary, now_unix_s: float) -> float:
    """How long the datagram waited before it was read: 0 unstamped or implausible."""
    held = now_unix_s - kernel_arrival_s(ancillary, now_unix_s, now_unix_s)
    return held if held <= MAX_HELD_S else 0.0
