"""One simulated vehicle's MAVLink endpoint: a UDP socket, its streams, commands and params.

Replies (COMMAND_ACK, PARAM_VALUE, requested messages) go to the sender; streamed
telemetry goes to the PX4-SITL-style default destination and to every address
that talked to the vehicle recently, bundled into one datagram per tick.
"""

from __future__ import annotations

import math
import socket
from collections import Counter
from collections.abc import Callable

from pymavlink.dialects.v20 import common as mavlink2

from agents.mavlink.modes import MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, decode_custom_mode
from agents.mavlink.signing import SignatureVerifier
from agents.mavlink.wire import decode_datagram, encode, frame_bytes, new_codec
from agents.scenario import HomeConfig
from sim_backend import telemetry as tm
from sim_backend.autopilot import ACCEPTED, DENIED, Autopilot
from sim_backend.params import ParamStore
from sim_backend.setpoint import SetpointRejected, decode_setpoint

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES = 520
PEER_TIMEOUT_S = 30.0
MAX_PEERS = 8
Addr = tuple[str, int]
Handler = Callable[[mavlink2.MAVLink_message, Addr], None]


class VehicleEndpoint:
    """MAVLink system `sysid` (component 1) bound to one UDP socket."""

    def __init__(self, sysid: int, sock: socket.socket, default_dest: Addr, autopilot: Autopilot,
                 params: ParamStore, home: HomeConfig, telemetry_hz: float,
                 counters: Counter[str], index: int = 0, tick_s: float = 0.01) -> None:
        self.sysid = sysid
        self.sock = sock
        self.default_dest = default_dest
        self.autopilot = autopilot
        self.params = params
        self.home = home
        self.counters = counters
        self.mav = new_codec(sysid, 1)
        self.peers: dict[Addr, float] = {}
        # Services that own a message type (sim_backend.timesync: TIMESYNC, SYSTEM_TIME).
        self.handlers: dict[str, Handler] = {}
        fast = 1.0 / telemetry_hz
        self.default_intervals: dict[int, float] = {
            tm.MSG_HEARTBEAT: 1.0, tm.MSG_SYS_STATUS: 1.0, tm.MSG_EXTENDED_SYS_STATE: 1.0,
            tm.MSG_HOME_POSITION: 5.0, tm.MSG_LOCAL_POSITION_NED: fast,
            tm.MSG_GLOBAL_POSITION_INT: fast, tm.MSG_ATTITUDE: fast,
        }
        self.intervals = dict(self.default_intervals)
        # Vehicle `index` starts each stream at its own tick within the stream's period, so
        # that all ticks carry about the same work instead of a burst once per period.
        self.next_due: dict[int, float] = {
            msg_id: (index % max(1, round(interval / tick_s))) * tick_s
            for msg_id, interval in self.intervals.items()}
        self._announced: tuple[str, bool] = ("", False)
        # Set when the vehicle enforces MAVLink 2 signing (like PX4 with a key): received
        # messages failing it are dropped and counted (signing_rejected_<reason>).
        self.verifier: SignatureVerifier | None = None

    # ---- receive ------------------------------------------------------------------------
    def on_datagram(self, data: bytes, addr: Addr, now_s: float, row: tm.Row) -> None:
        self.counters["rx_datagrams"] += 1
        decoded = decode_datagram(self.mav, data)
        if decoded.bad:
            self.counters["bad_packets"] += decoded.bad
        messages = [m for m in decoded.messages if self._signed_ok(m)]
        if messages:
            self._remember(addr, now_s)
        for msg in messages:
            self._dispatch(msg, addr, now_s, row)

    def _signed_ok(self, msg: mavlink2.MAVLink_message) -> bool:
        if self.verifier is None:
            return True
        reason = self.verifier.check(frame_bytes(msg), msg.get_msgId(), msg.get_srcSystem(),
                                     msg.get_srcComponent())
        if reason is not None:
            self.counters[f"signing_rejected_{reason}"] += 1
        return reason is None

    def _remember(self, addr: Addr, now_s: float) -> None:
        if addr not in self.peers and len(self.peers) >= MAX_PEERS:
            oldest = min(self.peers, key=self.peers.__getitem__)
            del self.peers[oldest]
        self.peers[addr] = now_s

    def _for_me(self, msg: mavlink2.MAVLink_message) -> bool:
        if msg.target_system not in (0, self.sysid):
            self.counters["ignored_other_sysid"] += 1
            return False
        return True

    def _dispatch(self, msg: mavlink2.MAVLink_message, addr: Addr, now_s: float,
                  row: tm.Row) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            return
        handler = self.handlers.get(kind)
        if handler is not None:
            handler(msg, addr)
            return
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            if self._for_me(msg):
                self._setpoint(msg, now_s, row)
        elif kind == "COMMAND_LONG":
            if self._for_me(msg):
                params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5,
                          msg.param6, msg.param7)
                self._command(msg, params, addr, now_s, row)
        elif kind == "COMMAND_INT":
            if self._for_me(msg):
                params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.x * 1e-7,
                          msg.y * 1e-7, msg.z)
                self._command(msg, params, addr, now_s, row)
        elif kind == "SET_MODE":
            if self._for_me(msg) and msg.base_mode & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                name = decode_custom_mode(self.autopilot.flavour, msg.custom_mode)
                self.autopilot.set_mode(name, now_s, row.pos, row.landed)
        elif kind in ("PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET"):
            if self._for_me(msg):
                self._param(msg, addr)
        else:
            self.counters["unhandled_messages"] += 1

    def _setpoint(self, msg: mavlink2.MAVLink_message, now_s: float, row: tm.Row) -> None:
        try:
            sp = decode_setpoint(msg.type_mask, msg.coordinate_frame, (msg.x, msg.y, msg.z),
                                 (msg.vx, msg.vy, msg.vz), msg.yaw, msg.yaw_rate,
                                 row.pos, row.yaw)
        except SetpointRejected as exc:
            key = "ignored_nonfinite" if "finite" in str(exc) else "ignored_setpoints"
            self.counters[key] += 1
            return
        self.counters["setpoints"] += 1
        self.autopilot.on_setpoint(sp, now_s, row.landed)

    def _command(self, msg: mavlink2.MAVLink_message, params: tuple[float, ...], addr: Addr,
                 now_s: float, row: tm.Row) -> None:
        self.counters["commands"] += 1
        reply: bytes | None = None
        cmd = msg.command
        if not all(math.isfinite(p) for p in params[:2]):
            result = DENIED
            self.counters["ignored_nonfinite"] += 1
        elif cmd in (MAV_CMD_REQUEST_MESSAGE, MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            wanted = tm.MSG_AUTOPILOT_VERSION if cmd != MAV_CMD_REQUEST_MESSAGE else int(params[0])
            reply = self.build(wanted, row)
            result = ACCEPTED if reply is not None else DENIED
        elif cmd == MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self._set_interval(int(params[0]), params[1], now_s)
        else:
            result = self.autopilot.command(cmd, params, now_s, row.pos, row.landed)
        if result != ACCEPTED:
            self.counters["commands_not_accepted"] += 1
        ack = self.mav.command_ack_encode(cmd, result, 0, 0, msg.get_srcSystem(),
                                          msg.get_srcComponent())
        self._send_to(encode(self.mav, ack) + (reply or b""), addr)

    def _set_interval(self, msg_id: int, interval_us: float, now_s: float) -> int:
        if msg_id not in self.default_intervals:
            return DENIED
        if interval_us < 0:
            self.intervals[msg_id] = 0.0
        elif interval_us == 0:
            self.intervals[msg_id] = self.default_intervals[msg_id]
        else:
            self.intervals[msg_id] = interval_us * 1e-6
        self.next_due[msg_id] = now_s
        return ACCEPTED

    def _param(self, msg: mavlink2.MAVLink_message, addr: Addr) -> None:
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            names = [self.params.name_at(k) for k in range(len(self.params))]
        elif kind == "PARAM_REQUEST_READ":
            by_index = self.params.name_at(msg.param_index) if msg.param_index >= 0 else None
            known = self.params.index_of(msg.param_id) >= 0
            names = [by_index or (msg.param_id if known else None)]
        else:
            ok = self.params.set_from_wire(msg.param_id, msg.param_value, msg.param_type)
            names = [msg.param_id if ok else None]
            self._apply_params()
        out = b""
        for name in names:
            if name is None:
                self.counters["ignored_params"] += 1
                continue
            value, ptype = self.params.wire(name)
            msg = self.mav.param_value_encode(name.encode(), value, ptype, len(self.params),
                                               self.params.index_of(name))
            out += encode(self.mav, msg)
        if out:
            self._send_to(out, addr)

    def _apply_params(self) -> None:
        for name in ("COM_OF_LOSS_T", "GUID_TIMEOUT"):
            if self.params.index_of(name) >= 0:
                self.autopilot.setpoint_timeout_s = self.params.get(name)
        if self.params.index_of("MIS_TAKEOFF_ALT") >= 0:
            self.autopilot.default_takeoff_alt_m = self.params.get("MIS_TAKEOFF_ALT")

    # ---- send ---------------------------------------------------------------------------
    def build(self, msg_id: int, row: tm.Row) -> bytes | None:
        """One packed message of id msg_id describing `row`, or None if not produced here."""
        if msg_id in tm.FAST_IDS:
            return tm.fast_bytes(self.mav, msg_id, row, self.home)
        ap = self.autopilot
        msg = tm.status_message(self.mav, msg_id, row, self.home, ap.flavour, ap.mode, ap.armed,
                                self.sysid)
        return None if msg is None else encode(self.mav, msg)

    def telemetry(self, now_s: float, row: tm.Row) -> None:
        """Send every stream that is due at sim time `now_s`, as one datagram per destination."""
        out = b""
        ap = self.autopilot
        if (ap.mode, ap.armed) != self._announced:
            # Announce mode and arming changes at once so clients need not wait up to 1 s.
            self._announced = (ap.mode, ap.armed)
            self.next_due[tm.MSG_HEARTBEAT] = now_s
        for msg_id, interval in self.intervals.items():
            # 1 us of slack: summed float periods (0.1 + 0.02 > 0.12) must not skip a tick.
            if interval <= 0.0 or now_s + 1e-6 < self.next_due[msg_id]:
                continue
            due = self.next_due[msg_id] + interval
            self.next_due[msg_id] = due if due > now_s else now_s + interval
            data = self.build(msg_id, row)
            if data is not None:
                out += data
        if not out:
            return
        stale = [a for a, t in self.peers.items() if now_s - t > PEER_TIMEOUT_S]
        for addr in stale:
            del self.peers[addr]
        self._send_to(out, self.default_dest)
        for addr in self.peers:
            if addr != self.default_dest:
                self._send_to(out, addr)

    def _send_to(self, data: bytes, addr: Addr) -> None:
        try:
            self.sock.sendto(data, addr)
            self.counters["tx_datagrams"] += 1
        except OSError:
            self.counters["tx_errors"] += 1
