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
import selectors
import socket
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from errors import LinkLostError, MavlinkError

if TYPE_CHECKING:  # the follower's process runs without numpy (issue 15)
    import numpy as np
from agents.mavlink import lean_common
from agents.mavlink.fast_rx import FastRx
from agents.mavlink.rx_gate import ADAPTER_BUDGET, RxGate
from agents.mavlink.signing import SignatureVerifier, signing_timestamp
from agents.mavlink.timemap import SO_TIMESTAMPNS, kernel_arrival_s
from agents.mavlink.udp import ANCILLARY_BYTES, bind_udp, kernel_drops
from agents.mavlink.vehicle_messages import Addr, VehicleMessages
from agents.mavlink.vehicle_types import AdapterConfig, VehicleState
from agents.mavlink.velocity_setpoint import velocity_fields
from agents.mavlink.wire import Framer, encode, new_codec, sign_outgoing, signature_ok
from agents.mavlink.wire_decode import MAVLinkMessage, decode_datagram

__all__ = ["AdapterConfig", "MavlinkAdapter", "VehicleState"]  # as imported from here
log = logging.getLogger(__name__)
MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID = 18, 8
HEARTBEAT_PERIOD_S = 1.0
TIMESYNC_PERIOD_S = 0.25
SETPOINT = lean_common.MAVLink_set_position_target_local_ned_message


class MavlinkAdapter(VehicleMessages):
    """Talks to one autopilot; never blocks except in `wait_readable`."""

    def __init__(self, cfg: AdapterConfig, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(cfg, clock)
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
        self._last_hb_tx_s = -math.inf
        self._link_reported_ok = False
        self._last_ts_tx_s = -math.inf
        self._t0 = clock()
        self.sock: socket.socket | None = None
        self._selector: selectors.BaseSelector | None = None
        # Called while a blocking start-up helper waits: a process re-arming its vehicle
        # mid-run keeps its status heartbeat going (agents.shell.vehicle_loop).
        self.on_wait: Callable[[], None] | None = None

    # ---- lifecycle ----------------------------------------------------------------------
    def open(self) -> MavlinkAdapter:
        self.sock = bind_udp(self.cfg.local_host, self.cfg.local_port,
                             self.remote if self.cfg.connect else None)
        self._selector = selectors.DefaultSelector()
        self._selector.register(self.sock, selectors.EVENT_READ)
        return self

    def close(self) -> None:
        if self._selector is not None:
            self._selector.close()
            self._selector = None
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def __enter__(self) -> MavlinkAdapter:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- receive (what is heard is applied by VehicleMessages) ---------------------------
    def poll(self) -> VehicleState:
        """Read what the tick's budget allows (agents.mavlink.rx_gate: the rest waits in the
        socket), keep our heartbeat going, update the link flag; never blocks."""
        now = self.clock()
        self._poll_s = now
        gate = self.gate
        carried = gate.new_tick()
        if carried is not None and carried[1] is not None:  # last tick had no room for it
            self._datagram(carried[0], carried[1], carried[2])
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
        accepted, layered = self.fast.read(self.gate, data, addr, received)
        if accepted:
            self.apply(accepted, addr, received)
        if layered:
            self._datagram(layered, addr, received)

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

    def _send_bytes(self, data: bytes) -> None:
        if self.sock is None or self.remote is None:
            self.counters["tx_dropped"] += 1
            return
        try:
            self.sock.sendto(data, self.remote)
        except ConnectionRefusedError:
            self.counters["peer_unreachable"] += 1
        except OSError:
            self.counters["tx_errors"] += 1

