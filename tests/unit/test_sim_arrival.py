"""The simulator's arrival stamps (sim_backend.arrival) and TIMESYNC's midpoint answer."""

from __future__ import annotations

import socket
import struct
import time
from collections import Counter

import pytest

from agents.mavlink.timemap import SO_TIMESTAMPNS
from agents.mavlink.wire import new_codec
from sim_backend.arrival import ANCILLARY_BYTES, MAX_HELD_S, held_s, stamp_arrivals
from sim_backend.clock_services import ClockService

pytestmark = pytest.mark.timeout(30)


def timespec(t_s: float) -> list[tuple[int, int, bytes]]:
    sec = int(t_s)
    return [(socket.SOL_SOCKET, SO_TIMESTAMPNS, struct.pack("=qq", sec, round((t_s - sec) * 1e9)))]


def test_the_wait_is_now_minus_the_kernel_stamp() -> None:
    assert held_s(timespec(1000.25), 1000.5) == pytest.approx(0.25, abs=1e-6)


@pytest.mark.parametrize("ancillary", [
    [],  # no stamp asked or none given
    [(socket.SOL_SOCKET, SO_TIMESTAMPNS, b"\x00" * 8)],  # truncated
    [(socket.IPPROTO_IP, SO_TIMESTAMPNS, struct.pack("=qq", 999, 0))],  # another level
])
def test_no_usable_stamp_counts_as_no_wait(ancillary: list[tuple[int, int, bytes]]) -> None:
    assert held_s(ancillary, 1000.0) == 0.0


@pytest.mark.parametrize("now_s", [999.0, 1000.0 + MAX_HELD_S + 0.5])
def test_a_stamp_after_now_or_too_old_counts_as_no_wait(now_s: float) -> None:
    """A clock step (or a fake clock in a test) must not shift a TIMESYNC answer."""
    assert held_s(timespec(1000.0), now_s) == 0.0


@pytest.mark.realtime
def test_a_real_socket_stamps_a_datagram_between_its_send_and_its_read() -> None:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        rx.bind(("127.0.0.1", 0))
        assert stamp_arrivals(rx)
        before = time.time()
        tx.sendto(b"x", rx.getsockname())
        rx.settimeout(5.0)
        data, ancillary, _flags, _addr = rx.recvmsg(64, ANCILLARY_BYTES)
        after = time.time()
    finally:
        rx.close()
        tx.close()
    assert data == b"x"
    assert [kind for level, kind, _ in ancillary if level == socket.SOL_SOCKET] == [SO_TIMESTAMPNS]
    assert 0.0 <= held_s(ancillary, after) <= after - before + 1e-3


def test_a_timesync_request_that_waited_is_answered_at_the_midpoint_of_its_wait() -> None:
    """The client's offset is the round trip's midpoint: a wait before the answer must
    fall on both legs, so tc1 is the boot clock half the wait ago."""
    sent: list[bytes] = []
    svc = ClockService(new_codec(1, 1), lambda data, addr: sent.append(data), lambda: 10.0,
                       time.time, Counter(), held_s=lambda: 0.016)
    gcs = new_codec(255, 190)
    request = gcs.timesync_encode(0, 42)
    assert svc.on_timesync(request, ("127.0.0.1", 1)) == "answered"
    reply = gcs.parse_buffer(sent[0])[0]
    assert reply.ts1 == 42 and reply.tc1 == round((10.0 - 0.008) * 1e9)
    # A reply to the vehicle's own request: the round trip ends when it arrived.
    svc._requests.append(9_000_000_000)
    assert svc.on_timesync(gcs.timesync_encode(5, 9_000_000_000), ("127.0.0.1", 1)) == "handled"
    assert svc.last_rtt_s == pytest.approx(10.0 - 0.016 - 9.0)
