"""The agents' MAVLink adapter: one vehicle, one UDP socket we own, non-blocking.

Designed for a single-threaded follower loop: `poll()` drains the socket and
returns the latest `VehicleState`; `send_velocity_enu()` streams a setpoint.
Conversion between the agent's ENU and the vehicle's NED happens only through
`agents.frames`.  The same code flies PX4 (offboard) and ArduPilot (guided);
the flavour is read from the vehicle's HEARTBEAT.
"""

from __future__ import annotations

import logging
import math
import select
import selectors
import socket
import time
from collections import Counter
from collections.abc import Callable
from typing import TYPE_CHECKING

from errors import LinkLostError, MavlinkError

if TYPE_CHECKING:  # the follower's process runs without numpy (issue 15)
    import numpy as np
from agents.frames import ned_to_enu_xyz
from agents.mavlink import lean_common
from agents.mavlink.fast_rx import LOCAL_POSITION_NED, FastRx
from agents.mavlink.modes import (
    MAV_MODE_FLAG_SAFETY_ARMED,
    decode_custom_mode,
    flavour_of_autopilot,
)
from agents.mavlink.rx_gate import ADAPTER_BUDGET, RxGate
from agents.mavlink.signing import SignatureVerifier, signing_timestamp
from agents.mavlink.timemap import SO_TIMESTAMPNS, VehicleClock, kernel_arrival_s
from agents.mavlink.udp import ANCILLARY_BYTES, bind_udp, kernel_drops
from agents.mavlink.vehicle_types import NO_STATE, AdapterConfig, VehicleState
from agents.mavlink.velocity_setpoint import velocity_fields
from agents.mavlink.wire import (
    Framer,
    MAVLinkMessage,
    decode_datagram,
    encode,
    new_codec,
    sign_outgoing,
    signature_ok,
)

log = logging.getLogger(__name__)
Addr = tuple[str, int]
MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID = 18, 8
HEARTBEAT_PERIOD_S = 1.0
MAV_SEVERITY_WARNING = 4
STATUSTEXT_KEPT = 20
TIMESYNC_PERIOD_S = 0.25
SETPOINT = lean_common.MAVLink_set_position_target_local_ned_message
# What `handle` does more with than hear the vehicle: HEARTBEAT, GLOBAL_POSITION_INT,
# COMMAND_ACK, TIMESYNC (of the types FastRx reads; LOCAL_POSITION_NED it reads itself).
HANDLED_IDS = frozenset({0, 33, 77, 111})


class MavlinkAdapter:
    """Talks to one autopilot; never blocks except in `wait_readable`."""

    def __init__(self, cfg: AdapterConfig, clock: Callable[[], float] = time.monotonic) -> None:
        self.cfg = cfg
        self.clock = clock
        self.counters: Counter[str] = Counter()
        # The lean dialect: the types we use and a real autopilot streams at rate, not
        # common's hundreds (~4.8 MB a process); the rest count as unknown_types.
        self.mav = new_codec(cfg.own_sysid, cfg.own_compid, lean_common)
        self.tx = self.mav  # the codec that packs what we send: a signing one when keyed
        self.verifier: SignatureVerifier | None = None
        if cfg.signing_key is not None:
            self.verifier = SignatureVerifier(cfg.signing_key, allowed_unsigned=frozenset(),
                                              evictions=self.counters)
            self.tx = new_codec(cfg.own_sysid, cfg.own_compid, lean_common)
            sign_outgoing(self.tx, cfg.signing_key, cfg.signing_link_id,
                          signing_timestamp(time.time()))
        # What is sent at rate, framed in one pass (wire.Framer); fields in wire order.
        self.setpoints = Framer(self.tx, SETPOINT)
        self.heartbeats = Framer(self.tx, lean_common.MAVLink_heartbeat_message)
        self.timesyncs = Framer(self.tx, lean_common.MAVLink_timesync_message)
        self.fast = FastRx(self.mav, self.verifier, self.counters)
        self.gate = RxGate(f"vehicle {cfg.target_sysid or '?'} link", ADAPTER_BUDGET,
                           self.counters, self.verifier)
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
        self._last_hb_tx_s = -math.inf
        self._link_reported_ok = False
        self.vclock = VehicleClock(f"vehicle {cfg.target_sysid or '?'}")
        self._last_ts_tx_s = -math.inf
        self._poll_s = -math.inf
        self._t0 = clock()
        self.sock: socket.socket | None = None
        self._selector: selectors.BaseSelector | None = None
        self._probe: select.poll | None = None
        # Called while a blocking start-up helper waits: a process re-arming its vehicle
        # mid-run keeps its status heartbeat going (agents.shell.vehicle_loop).
        self.on_wait: Callable[[], None] | None = None

    # ---- lifecycle ----------------------------------------------------------------------
    def open(self) -> MavlinkAdapter:
        self.sock = bind_udp(self.cfg.local_host, self.cfg.local_port,
                             self.remote if self.cfg.connect else None)
        self._selector = selectors.DefaultSelector()
        self._selector.register(self.sock, selectors.EVENT_READ)
        self._probe = select.poll()
        self._probe.register(self.sock, select.POLLIN)
        return self

    def close(self) -> None:
        if self._selector is not None:
            self._selector.close()
            self._selector = None
        self._probe = None
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def __enter__(self) -> MavlinkAdapter:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- receive ------------------------------------------------------------------------
    @property
    def state(self) -> VehicleState:
        return self._state

    @property
    def telemetry_seen(self) -> bool:
        """A position ever arrived: from then on `state.link_ok` says if it is heard."""
        return self._last_rx_s > -math.inf

    def poll(self) -> VehicleState:
        """Read what the tick's budget allows (agents.mavlink.rx_gate: the rest waits in the
        socket), keep our heartbeat going, update the link flag; never blocks."""
        now = self.clock()
        self._poll_s = now
        gate = self.gate
        carried = gate.new_tick()
        if carried is not None and carried[1] is not None:  # last tick had no room for it
            self._datagram(carried[0], carried[1], carried[2])
        probe = self._probe
        while self.sock is not None and gate.open:
            try:
                data, anc, _flags, addr = self.sock.recvmsg(65535, ANCILLARY_BYTES)
            except (BlockingIOError, InterruptedError):
                break
            except ConnectionRefusedError:  # connected, and the vehicle is not (yet) there
                self.counters["peer_unreachable"] += 1
                break
            except OSError:
                self.counters["rx_errors"] += 1
                break
            # A drop count comes only after drops, beside the arrival stamp.
            if anc and (len(anc) > 1 or anc[0][1] != SO_TIMESTAMPNS) and \
                    (dropped := kernel_drops(anc)) is not None:
                self.counters["mav_kernel_drops"] = dropped
            self._take(data, addr, kernel_arrival_s(anc, time.time(), self.clock()))
            # Stop when the socket is empty: a zero-timeout poll is cheaper than the
            # exception of a read that finds nothing.
            if probe is not None and not probe.poll(0):
                break
        if now - self._last_hb_tx_s >= HEARTBEAT_PERIOD_S and self.remote is not None:
            self._last_hb_tx_s = now
            self._send_framed(self.heartbeats, 0, MAV_TYPE_ONBOARD_CONTROLLER,
                              MAV_AUTOPILOT_INVALID, 0, 4, 3)
        if now - self._last_ts_tx_s >= TIMESYNC_PERIOD_S and self.sysid is not None:
            self._last_ts_tx_s = now
            self._send_framed(self.timesyncs, 0, self.vclock.request(self.clock()))
        return self._update_link(now)

    def _take(self, data: bytes, addr: Addr, received: float) -> None:
        """A datagram off the socket: FastRx takes what it can judge, the gate's screen and
        `_datagram` the rest (agents.mavlink.fast_rx: the same verdicts either way)."""
        gate, rest, refused = self.gate, 0, None
        if gate.fits(len(data)):
            accepted, rest, refused = self.fast.scan(data)
        if refused is not None:
            gate.refuse(refused, addr)
            return
        if rest == 0:
            admitted = gate.admit(data, addr, received)
            if admitted:
                self._datagram(admitted, addr, received)
            return
        gate.take(len(data))
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
        if rest < len(data):
            self._datagram(data[rest:], addr, received)

    def _handler_error(self, kind: object) -> None:
        self.counters["handler_errors"] += 1
        if self.counters["handler_errors"] <= 5:
            log.exception("vehicle %s: cannot handle %s", self.sysid, kind)

    def _datagram(self, data: bytes, addr: Addr, received: float) -> None:
        decoded = decode_datagram(self.mav, data)
        self.counters["bad_packets"] += decoded.bad
        if decoded.unknown:  # BATTERY_STATUS, PARAM_VALUE...: framed, not ours
            self.counters["unknown_types"] += decoded.unknown
        for msg in decoded.messages:
            if not signature_ok(self.verifier, msg, self.counters):
                continue
            try:
                self.handle(msg, addr, received)
            except Exception:  # a hostile or odd packet must not stop the follower
                self._handler_error(msg.get_type())

    def wait_readable(self, timeout_s: float) -> None:
        """Block until a datagram is queued or timeout_s passes (start-up helpers only)."""
        if self.on_wait is not None:
            self.on_wait()
        if self._selector is not None:
            self._selector.select(max(0.0, timeout_s))

    def check_link(self) -> None:
        """Raise LinkLostError when no telemetry arrived within the link timeout."""
        if not self._state.link_ok:
            raise LinkLostError(f"no telemetry from vehicle {self.sysid} for "
                                f">= {self.cfg.link_timeout_s} s")

    def _update_link(self, now: float) -> VehicleState:
        ok = now - self._last_rx_s < self.cfg.link_timeout_s
        if ok != self._link_reported_ok:
            self._link_reported_ok = ok
            if ok:
                log.info("link to vehicle %s up (%s)", self.sysid, self.flavour)
            else:
                self.counters["link_losses"] += 1
                log.warning("link to vehicle %s lost: no telemetry for %.2f s", self.sysid,
                            self.cfg.link_timeout_s)
        if ok != self._state.link_ok:
            self._state = self._state._replace(link_ok=ok)
        return self._state

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

    # ---- clock --------------------------------------------------------------------------
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

    # ---- send ---------------------------------------------------------------------------
    def send_velocity_enu(self, vel_m_s: tuple[float, float, float] | np.ndarray,
                          yaw_enu_rad: float | None = None) -> bool:
        """Stream one velocity setpoint; False (and counted) when refused."""
        fields = velocity_fields(vel_m_s, yaw_enu_rad, self._boot_ms(), self.sysid or 0)
        if fields is None:
            self.counters["refused_nonfinite"] += 1
            return False
        if self.sysid is None or self.remote is None:
            self.counters["refused_not_connected"] += 1
            return False
        self._send_bytes(self.setpoints.frame(*fields))
        self.counters["setpoints_sent"] += 1
        return True

    def send_command(self, command: int, params: tuple[float, ...], confirmation: int = 0) -> None:
        """COMMAND_LONG with up to 7 params; clears any earlier ACK of the same command."""
        if self.sysid is None:
            raise MavlinkError("no vehicle heartbeat yet")
        p = list(params) + [0.0] * (7 - len(params))
        self.acks.pop(command, None)
        self._send(self.mav.command_long_encode(self.sysid, 1, command, confirmation, *p))

    def _boot_ms(self) -> int:
        return int((self.clock() - self._t0) * 1000.0) & 0xFFFFFFFF

    def _send(self, msg: MAVLinkMessage) -> None:
        if self.sock is None or self.remote is None:
            self.counters["tx_dropped"] += 1
            return
        self._send_bytes(encode(self.tx, msg))

    def _send_framed(self, framer: Framer, *fields: float) -> None:
        """`fields` (wire order) framed by `framer` and sent, as `_send` sends a message."""
        if self.sock is None or self.remote is None:
            self.counters["tx_dropped"] += 1
            return
        self._send_bytes(framer.frame(*fields))

    def _send_bytes(self, data: bytes | bytearray) -> None:
        if self.sock is None or self.remote is None:
            self.counters["tx_dropped"] += 1
            return
        try:
            self.sock.sendto(data, self.remote)
        except ConnectionRefusedError:
            self.counters["peer_unreachable"] += 1
        except OSError:
            self.counters["tx_errors"] += 1

