"""A simulated autopilot's clock services: TIMESYNC and SYSTEM_TIME, as PX4 keeps them.

- A TIMESYNC request (tc1 == 0) is answered with tc1 = the vehicle's boot clock in ns and
  ts1 mirrored (PX4's `Timesync::handle_message`: hrt_absolute_time() * 1000).  Clients
  map the vehicle's time_boot_ms onto their own clock from these replies.  The simulator
  handles what arrived during a tick at the tick's end (sim_backend.runtime), so tc1 is
  the boot clock half-way between the request's arrival (the kernel's stamp,
  sim_backend.arrival) and the reply: the wait then falls evenly on both legs of the
  round trip, and the client's midpoint estimate stays unbiased, as with PX4's answer at
  once.
- The vehicle originates a request every `period_s` (ts1 = its boot clock, ns), as PX4's
  TIMESYNC stream does; a reply carrying one of its recent ts1 gives the round trip to its
  partner, counted (the simulated vehicle needs no offset: nothing it does is stamped by
  its partners' clocks).
- It streams SYSTEM_TIME (Unix time, boot ms).  A received SYSTEM_TIME changes nothing:
  PX4 takes it only while its own clock is before 2009, and the simulator's never is.
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Callable
from typing import Protocol

from pymavlink.dialects.v20 import common as mavlink2

from agents.mavlink.rx_gate import Addr
from agents.mavlink.wire import encode_fields

TIMESYNC = mavlink2.MAVLink_timesync_message
SYSTEM_TIME = mavlink2.MAVLink_system_time_message

Handler = Callable[[mavlink2.MAVLink_message, Addr], str]  # returns the outcome
REMEMBERED_REQUESTS = 8


class HasHandlers(Protocol):
    handlers: dict[str, Handler]


class ClockService:
    """TIMESYNC and SYSTEM_TIME of one vehicle; `boot_s` is its boot clock in seconds."""

    def __init__(self, mav: mavlink2.MAVLink, send: Callable[[bytes, Addr], None],
                 boot_s: Callable[[], float], unix_s: Callable[[], float],
                 counters: Counter[str], period_s: float = 1.0,
                 held_s: Callable[[], float] = lambda: 0.0) -> None:
        self.mav, self._send = mav, send  # the endpoint's send (counts tx and its errors)
        self.boot_s, self.unix_s = boot_s, unix_s
        self.held_s = held_s  # how long the message being handled waited to be read
        self.counters = counters
        self.period_s = period_s
        self.last_rtt_s: float | None = None
        self._next_s = 0.0
        self._requests: deque[int] = deque(maxlen=REMEMBERED_REQUESTS)

    def attach(self, endpoint: HasHandlers) -> ClockService:
        endpoint.handlers["TIMESYNC"] = self.on_timesync
        endpoint.handlers["SYSTEM_TIME"] = self.on_system_time
        return self

    def on_timesync(self, msg: mavlink2.MAVLink_message, addr: Addr) -> str:
        now_s, held = self.boot_s(), self.held_s()
        if msg.tc1 == 0:
            self.counters["timesync_answered"] += 1
            now_ns = max(1, round((now_s - 0.5 * held) * 1e9))  # 0 would read as a request
            # Packed from its fields (the same bytes: tests/unit/test_mavlink_wire.py): each
            # agent asks 4 times a second: 256 answers a second in ring64's simulator, 1.9
            # instead of 4.4 us each, signed.
            self._send(encode_fields(self.mav, TIMESYNC, now_ns, msg.ts1), addr)
            return "answered"
        if msg.ts1 in self._requests:
            self.counters["timesync_replies"] += 1
            self.last_rtt_s = now_s - held - msg.ts1 * 1e-9  # to the reply's arrival
            return "handled"
        self.counters["timesync_ignored"] += 1  # a reply to a request we did not send
        return "ignored"

    def on_system_time(self, msg: mavlink2.MAVLink_message, addr: Addr) -> str:
        self.counters["system_time_ignored"] += 1
        return "ignored"

    def due(self, dest: Addr) -> None:
        """Send our TIMESYNC request and SYSTEM_TIME to `dest` when the period has passed."""
        boot_s = self.boot_s()
        if boot_s < self._next_s:
            return
        self._next_s = boot_s + self.period_s
        ts1 = round(boot_s * 1e9)
        self._requests.append(ts1)
        data = encode_fields(self.mav, TIMESYNC, 0, ts1)
        data += encode_fields(self.mav, SYSTEM_TIME, round(self.unix_s() * 1e6),
                              round(boot_s * 1e3) & 0xFFFFFFFF)
        self._send(data, dest)
