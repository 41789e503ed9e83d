"""What an adapter knows of its vehicle from the messages it hears: state, flavour, clock.

The receiving half of `agents.mavlink.adapter.MavlinkAdapter`, apart from its socket: it
applies messages that passed the link's checks, as pymavlink message objects (`handle`)
or as the fields agents.mavlink.fast_rx unpacked (`apply`).  It sends only TIMESYNC
answers, through the adapter's `_send_framed`.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Callable
from typing import Any

from agents.frames import ned_to_enu_xyz
from agents.mavlink.fast_rx import LOCAL_POSITION_NED, Accepted
from agents.mavlink.modes import (
    MAV_MODE_FLAG_SAFETY_ARMED,
    decode_custom_mode,
    flavour_of_autopilot,
)
from agents.mavlink.rx_gate import Addr
from agents.mavlink.timemap import VehicleClock
from agents.mavlink.vehicle_types import NO_STATE, AdapterConfig, VehicleState
from agents.mavlink.wire import Framer
from agents.mavlink.wire_decode import Codec, MAVLinkMessage, decode_datagram

log = logging.getLogger("agents.mavlink.adapter")
MAV_SEVERITY_WARNING = 4
STATUSTEXT_KEPT = 20
# What `handle` does more with than hear the vehicle: HEARTBEAT, GLOBAL_POSITION_INT,
# COMMAND_ACK, TIMESYNC (of the types FastRx reads; LOCAL_POSITION_NED `apply` reads).
HANDLED_IDS = frozenset({0, 33, 77, 111})


class VehicleMessages:
    """One vehicle's state as its messages tell it; the adapter adds the link."""

    mav: Codec  # decodes what `apply` hands to `handle`
    timesyncs: Framer

    def __init__(self, cfg: AdapterConfig, clock: Callable[[], float]) -> None:
        self.cfg = cfg
        self.clock = clock
        self.counters: Counter[str] = Counter()
        self.sysid = cfg.target_sysid
        self.flavour: str | None = None
        self.remote: Addr | None = None if cfg.remote_port is None else (cfg.remote_host,
                                                                         cfg.remote_port)
        self.home_amsl_m: float | None = None
        self.acks: dict[int, int] = {}
        self.statustexts: list[str] = []
        self.statustext_count = 0
        self._state = NO_STATE
        self._armed, self._mode = False, "UNKNOWN"
        self._last_rx_s = -math.inf
        self.heard_s = -math.inf  # our clock when the vehicle last sent anything
        self.vclock = VehicleClock(f"vehicle {cfg.target_sysid or '?'}")
        self._poll_s = -math.inf

    @property
    def state(self) -> VehicleState:
        return self._state

    @property
    def telemetry_seen(self) -> bool:
        """A position ever arrived: from then on `state.link_ok` says if it is heard."""
        return self._last_rx_s > -math.inf

    def apply(self, accepted: list[Accepted], addr: Addr, received: float) -> None:
        """Apply the frames FastRx accepted, in order; a failing one is counted."""
        for msg_id, sysid, compid, body in accepted:
            try:
                if msg_id == LOCAL_POSITION_NED:
                    if self._from_vehicle(sysid, compid, received):
                        self._position(body, received)
                elif msg_id in HANDLED_IDS:  # at a few Hz: as a message object
                    for msg in decode_datagram(self.mav, body).messages:
                        self.handle(msg, addr, received)
                else:
                    self._from_vehicle(sysid, compid, received)
            except Exception:  # a hostile or odd packet must not stop the follower
                self._handler_error(msg_id)

    def handle(self, msg: MAVLinkMessage, addr: Addr, now: float) -> None:
        """Apply one received message (public so unit tests can feed messages directly)."""
        src = msg.get_srcSystem()
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if self._heartbeat(msg, addr):
                self.heard_s = now
            return
        if not self._from_vehicle(src, msg.get_srcComponent(), now):
            return
        if kind == "LOCAL_POSITION_NED":
            self._position((msg.time_boot_ms, msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz), now)
        elif kind == "TIMESYNC":
            self._timesync(msg, now)
        elif kind == "COMMAND_ACK":
            self.acks[msg.command] = msg.result
        elif kind == "STATUSTEXT":
            self._statustext(msg)
        elif kind == "GLOBAL_POSITION_INT":
            self.home_amsl_m = (msg.alt - msg.relative_alt) * 1e-3
        elif kind == "HOME_POSITION":
            self.home_amsl_m = msg.altitude * 1e-3

    def _statustext(self, msg: MAVLinkMessage) -> None:
        """Keep the vehicle's recent STATUSTEXTs: the reasons behind refusals and failsafes."""
        text = str(msg.text).rstrip("\x00")
        self.statustexts.append(text)
        del self.statustexts[:-STATUSTEXT_KEPT]
        self.statustext_count += 1
        if msg.severity <= MAV_SEVERITY_WARNING:
            log.warning("vehicle %s says: %s", self.sysid, text)

    def statustexts_since(self, count: int) -> list[str]:
        """The STATUSTEXTs received after the `statustext_count` value `count` (newest last)."""
        return self.statustexts[len(self.statustexts) - min(self.statustext_count - count,
                                                            len(self.statustexts)):]

    def _heartbeat(self, msg: MAVLinkMessage, addr: Addr) -> bool:
        """Apply our vehicle's HEARTBEAT; False if it is somebody else's."""
        flavour = flavour_of_autopilot(msg.autopilot)
        src = msg.get_srcSystem()
        if flavour is None or msg.get_srcComponent() != 1:
            return False  # ground stations, companions, gimbals: not our vehicle
        if self.sysid is None:
            self.sysid = src
        if src != self.sysid:
            self.counters["ignored_other_system"] += 1
            return False
        if self.flavour is None:
            log.info("vehicle %d is %s at %s:%d", src, flavour, *addr)
        self.flavour = flavour
        self.remote = addr
        self._armed = bool(msg.base_mode & MAV_MODE_FLAG_SAFETY_ARMED)
        self._mode = decode_custom_mode(flavour, msg.custom_mode)
        self._state = self._state._replace(armed=self._armed, mode=self._mode)
        return True

    def _from_vehicle(self, sysid: int, compid: int, now: float) -> bool:
        """Whether a message other than a HEARTBEAT is our vehicle's (then it is heard)."""
        if self.sysid is None or sysid != self.sysid or compid != 1:
            self.counters["ignored_other_system"] += 1
            return False
        self.heard_s = now
        return True

    def _position(self, fields: tuple[int, float, float, float, float, float, float],
                  now: float) -> None:
        """LOCAL_POSITION_NED's fields in wire order: time_boot_ms, x, y, z, vx, vy, vz."""
        boot_ms, x, y, z, vx, vy, vz = fields
        if not math.isfinite(x + y + z + vx + vy + vz):  # any NaN or inf makes the sum so
            self.counters["ignored_nonfinite"] += 1
            return
        # The link is judged by when we read telemetry (as before arrival stamps): only
        # the sample's own stamp needs its true arrival time.
        self._last_rx_s = max(now, self._poll_s)
        stamp = self.vclock.map.stamp(boot_ms * 1e-3, now)
        self._state = VehicleState(ned_to_enu_xyz(x, y, z), ned_to_enu_xyz(vx, vy, vz), stamp,
                                   self._armed, self._mode, True)

    def _timesync(self, msg: MAVLinkMessage, now: float) -> None:
        """Answer the vehicle's requests (our clock, ns); fold replies to ours into the map."""
        if msg.tc1 == 0:
            self._send_framed(self.timesyncs, round(self.clock() * 1e9), msg.ts1)
            self.counters["timesync_answered"] += 1
        else:
            self.vclock.reply(msg.tc1, msg.ts1, now)

    def clock_counters(self) -> dict[str, int]:
        """How the vehicle's clock is mapped: TIMESYNC locked (1/0), re-locks, reboots."""
        return self.vclock.counters()

    def _handler_error(self, kind: object) -> None:
        self.counters["handler_errors"] += 1
        if self.counters["handler_errors"] <= 5:
            log.exception("vehicle %s: cannot handle %s", self.sysid, kind)

    def _send_framed(self, framer: Framer, *fields: Any) -> None:
        raise NotImplementedError  # the adapter sends
