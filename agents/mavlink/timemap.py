"""Map a vehicle's time_boot_ms onto the agent's clock: the one place that maps clocks.

Two estimates of offset = agent time - vehicle boot time:
- TIMESYNC round trips (`agents.mavlink.timesync`), used once locked: the vehicle's
  clock itself, independent of how late its telemetry arrives;
- for vehicles that do not answer TIMESYNC, the minimum of (receive time - boot time)
  over the last `window_s` of telemetry: the least-delayed packet of a recent window.
  A minimum kept forever never forgives: after the vehicle's clock lost time (a
  simulator that dropped a stall) every later sample would be stamped that much too
  old for the rest of the run.  The window forgets such an offset in `window_s`.
A boot time going backwards by more than REBOOT_JUMP_S means the vehicle rebooted:
both estimates start over (counted, logged).  No stamp is ever later than its receipt.
"""

from __future__ import annotations

import logging
import math
import socket
import struct
from collections import deque

from agents.mavlink.timesync import TimesyncEstimator, TimesyncParams

log = logging.getLogger(__name__)
REBOOT_JUMP_S = 1.0
WINDOW_S = 2.0
PENDING_REQUESTS = 16  # our TIMESYNC requests whose replies are still accepted
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux; Python does not export it
_TIMESPEC = struct.Struct("qq")


def kernel_arrival_s(ancillary: list[tuple[int, int, bytes]], wall_s: float,
                     now_s: float) -> float:
    """Agent-clock arrival time of a datagram: `now_s`, less how long the kernel held it
    (its SO_TIMESTAMPNS wall-clock stamp against `wall_s`); `now_s` without a stamp.

    The caller reads both clocks back to back, after recvmsg: a `now` read before a
    descheduling would turn the time we were away into a wrong age of every datagram.
    """
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(data) >= 16:
            sec, nsec = _TIMESPEC.unpack_from(data)
            return now_s - min(1.0e6, max(0.0, wall_s - (sec + nsec * 1e-9)))
    return now_s


class WindowedMinOffset:
    """Minimum of received - boot over the samples received in the last `window_s`."""

    def __init__(self, window_s: float = WINDOW_S) -> None:
        self.window_s = window_s
        self._newest_s = -math.inf
        # (received_s, offset_s) with increasing offsets: the front is the window's minimum.
        self._mins: deque[tuple[float, float]] = deque()

    def clear(self) -> None:
        self._mins.clear()
        self._newest_s = -math.inf

    def add(self, boot_s: float, received_s: float) -> float:
        """Fold one sample in and return the window's minimum offset."""
        offset = received_s - boot_s
        self._newest_s = max(self._newest_s, received_s)
        while self._mins and self._mins[-1][1] >= offset:
            self._mins.pop()
        self._mins.append((received_s, offset))
        horizon = self._newest_s - self.window_s
        while len(self._mins) > 1 and self._mins[0][0] < horizon:
            self._mins.popleft()
        return self._mins[0][1]


class BootClockMap:
    """Vehicle boot time -> agent time, from TIMESYNC when locked, else a windowed minimum."""

    def __init__(self, window_s: float = WINDOW_S, params: TimesyncParams | None = None,
                 name: str = "vehicle") -> None:
        self.name = name
        self.fallback = WindowedMinOffset(window_s)
        self.timesync = TimesyncEstimator(params, name)
        self._last_boot_s = -math.inf
        self.reboots = 0

    @property
    def resets(self) -> int:
        """Clock resets: TIMESYNC re-locks (offset jumps) and reboots seen in telemetry."""
        return self.timesync.resets

    def timesync_sample(self, sent_s: float, vehicle_s: float, received_s: float) -> bool:
        return self.timesync.add(sent_s, vehicle_s, received_s)

    def stamp(self, boot_s: float, received_s: float) -> float:
        """Agent-clock time of a sample the vehicle stamped `boot_s`, received at `received_s`."""
        if boot_s < self._last_boot_s - REBOOT_JUMP_S:
            self.reboots += 1
            log.warning("%s rebooted (boot time %.3f s after %.3f s): clock map reset",
                        self.name, boot_s, self._last_boot_s)
            self.fallback.clear()
            self.timesync.reset("reboot")
        self._last_boot_s = boot_s
        offset = self.fallback.add(boot_s, received_s)
        if self.timesync.locked:
            offset = self.timesync.offset_at(received_s)
        return min(boot_s + offset, received_s)


class VehicleClock:
    """A BootClockMap with the bookkeeping of our own TIMESYNC requests (ts1 in ns)."""

    def __init__(self, name: str = "vehicle") -> None:
        self.map = BootClockMap(name=name)
        self.unmatched = 0
        self._sent: dict[int, float] = {}

    def request(self, now_s: float) -> int:
        """ts1 of a new request sent at `now_s`."""
        ts1 = round(now_s * 1e9)
        self._sent[ts1] = now_s
        while len(self._sent) > PENDING_REQUESTS:
            del self._sent[next(iter(self._sent))]
        return ts1

    def reply(self, tc1_ns: int, ts1_ns: int, received_s: float) -> None:
        """A reply to a request of ours (else counted: not ours, or a duplicate)."""
        sent = self._sent.pop(ts1_ns, None)
        if sent is None:
            self.unmatched += 1
            return
        self.map.timesync_sample(sent, tc1_ns * 1e-9, received_s)

    def counters(self) -> dict[str, int]:
        m = self.map
        return {"timesync_locked": int(m.timesync.locked), "clock_resets": m.resets,
                "vehicle_reboots": m.reboots, "timesync_unmatched": self.unmatched,
                "timesync_dropped": m.timesync.counters["timesync_dropped_rtt"]}
