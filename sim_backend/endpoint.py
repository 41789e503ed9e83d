"""One simulated vehicle's MAVLink endpoint: a UDP socket, its streams and its one dispatch.

`on_datagram` is the single entry point for received bytes and `HANDLERS` the single
message dispatch (commands live in `sim_backend.commands`, the ground-station protocols
in `sim_backend.protocols`).  Every message is handled inside its own error boundary:
a handler that raises is counted and answered (FAILED + STATUSTEXT), never propagated,
so no packet can stop the simulator.  Each message is counted by type and outcome in
`messages` ("answered", "handled", "ignored", "refused", "failed", "unhandled").  A
well-framed frame of a type the common dialect lacks (a bigger dialect's, as MAVProxy's
ardupilotmega, or garbage that happens to frame) cannot be CRC-checked: it is counted as
`unknown_types`, apart from `bad_packets`, and has no outcome.

Replies (COMMAND_ACK, PARAM_VALUE, requested messages) go to the sender; streamed
telemetry goes to the PX4-SITL-style default destination and to every address
that talked to the vehicle recently (its peers, sim_backend.peers; a signed sender a full
table refuses is counted as `peers_refused`), bundled into one datagram per tick.

What is read per tick is bounded (agents.mavlink.rx_gate: `gate`, `VEHICLE_BUDGET`).
A datagram is walked once by agents.mavlink.fast_rx where it can judge it exactly as the
layered path (the gate's screen, `decode_datagram`, `signature_ok` per message) would: a
setpoint is then verified with one hash, not two, and flown from its unpacked fields
without a message object (its receive was half of the simulator's work per vehicle-tick).
"""

from __future__ import annotations

import logging
import socket
from collections import Counter
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from agents.mavlink.fast_rx import SET_POSITION_TARGET_LOCAL_NED, Accepted, FastRx
from agents.mavlink.rx_gate import VEHICLE_BUDGET, RxGate
from agents.mavlink.signing import IFLAG_SIGNED, SignatureVerifier
from agents.mavlink.wire import encode, new_codec, sign_outgoing, signature_ok
from agents.mavlink.wire_decode import MAVLinkMessage as Msg
from agents.mavlink.wire_decode import decode_datagram
from agents.scenario.model import HomeConfig
from sim_backend import commands, protocols
from sim_backend import telemetry as tm
from sim_backend.autopilot import SEVERITY_WARNING, Autopilot
from sim_backend.endpoint_view import Addr, EndpointView, Handler, MissionStore, Rx
from sim_backend.params import ParamStore
from sim_backend.peers import Peers

log = logging.getLogger(__name__)
MAX_LOGGED_ERRORS = 5
SETPOINT_KIND = "SET_POSITION_TARGET_LOCAL_NED"
ServiceHandler = Callable[[Msg, Addr], str]  # a service that owns a message type; outcome


class VehicleEndpoint:
    """MAVLink system `sysid` (component 1) bound to one UDP socket."""

    def __init__(self, sysid: int, sock: socket.socket, default_dest: Addr, autopilot: Autopilot,
                 params: ParamStore, home: HomeConfig, telemetry_hz: float,
                 counters: Counter[str], index: int = 0, tick_s: float = 0.01,
                 messages: Counter[str] | None = None) -> None:
        self.sysid = sysid
        self.sock = sock
        # The ancillary data of the datagram last read (its kernel arrival stamp, if any:
        # sim_backend.arrival), set by the loop that reads the socket.
        self.arrival: list[tuple[int, int, bytes]] = []
        self.default_dest = default_dest
        self.autopilot = autopilot
        self.params = params
        self.home = home
        self.counters = counters
        self.messages: Counter[str] = Counter() if messages is None else messages
        # The full common dialect: ground stations and SDKs speak all of it.
        self.mav = new_codec(sysid, 1, mavlink2)  # packs what we send (signs it when keyed)
        # Parses what we receive: never keyed, because pymavlink's own check moves a
        # stream's timestamp before it verifies (agents.mavlink.signing).
        self.rx_codec = new_codec(sysid, 1, mavlink2)
        self.peers = Peers()
        self.missions = MissionStore()
        # Services that own a message type (sim_backend.clock_services: TIMESYNC, SYSTEM_TIME).
        self.handlers: dict[str, ServiceHandler] = {}
        fast = 1.0 / telemetry_hz
        self.default_intervals: dict[int, float] = {
            tm.MSG_HEARTBEAT: 1.0, tm.MSG_SYS_STATUS: 1.0, tm.MSG_EXTENDED_SYS_STATE: 1.0,
            tm.MSG_HOME_POSITION: 5.0, tm.MSG_LOCAL_POSITION_NED: fast,
            tm.MSG_GLOBAL_POSITION_INT: fast, tm.MSG_ATTITUDE: fast, tm.MSG_GPS_RAW_INT: 0.2,
            tm.MSG_VFR_HUD: 0.25, tm.MSG_BATTERY_STATUS: 2.0,
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
        self.gate = RxGate(f"vehicle {sysid}", VEHICLE_BUDGET, counters)
        self.fast = FastRx(self.rx_codec, None, counters, SET_POSITION_TARGET_LOCAL_NED)
        protocols.apply_params(self)

    def enforce_signing(self, key: bytes, link_id: int = 0,
                        key_of_vehicle: Callable[[int], bytes | None] | None = None) -> None:
        """Behave as a PX4 vehicle with a signing key: drop what is not signed with it, and
        sign everything sent, so that forged telemetry is told apart at the agent too.
        `key_of_vehicle`: the other vehicles' keys, to name the key of a frame signed with
        one of them (agents.mavlink.signing.SignatureVerifier)."""
        self.verifier = SignatureVerifier(key, key_of_vehicle=key_of_vehicle,
                                          evictions=self.counters)
        self.gate.verifier = self.verifier
        self.fast = FastRx(self.rx_codec, self.verifier, self.counters,
                           SET_POSITION_TARGET_LOCAL_NED)
        sign_outgoing(self.mav, key, link_id, self.verifier.now_ticks())

    # ---- receive ------------------------------------------------------------------------
    def on_datagram(self, data: bytes, addr: Addr, now_s: float, row: tm.Row) -> None:
        """The one entry point for a received UDP datagram; never raises."""
        self.counters["rx_datagrams"] += 1
        accepted, layered = self.fast.read(self.gate, data, addr, now_s)
        if accepted:
            self._take_accepted(accepted, addr, Rx(addr, now_s, row))
        if layered:  # its sender remembered with the head, as parse_datagram would
            self.parse_datagram(layered, addr, now_s, row, remembered=bool(accepted))

    def _take_accepted(self, accepted: list[Accepted], addr: Addr, rx: Rx) -> None:
        """Frames FastRx accepted (verified, when signing is enforced), in order, as
        `parse_datagram` takes them: the sender remembered, each message dispatched."""
        self._remember(addr, rx.now_s)
        for msg_id, _sysid, _compid, body in accepted:
            if msg_id == SET_POSITION_TARGET_LOCAL_NED:
                self._setpoint(body, rx)
            else:  # a few a second: as a message object
                for msg in decode_datagram(self.rx_codec, body).messages:
                    self.dispatch(msg, rx)

    def _setpoint(self, f: tuple[Any, ...], rx: Rx) -> None:
        """`dispatch` of a SET_POSITION_TARGET_LOCAL_NED from its fields in wire order
        (time_boot_ms, x, y, z, vx, vy, vz, afx, afy, afz, yaw, yaw_rate, type_mask,
        target_system, target_component, coordinate_frame)."""
        if self._other_system(f[13]):
            outcome = "ignored"
        else:
            try:
                outcome = commands.apply_setpoint(
                    self, f[12], f[15], (f[1], f[2], f[3]), (f[4], f[5], f[6]),
                    f[10], f[11], rx)
            except Exception:  # as dispatch: count it, answer it, keep flying
                outcome = "failed"
                self._failed(SETPOINT_KIND, None, rx)
        self.messages[f"{SETPOINT_KIND}:{outcome}"] += 1

    def parse_datagram(self, data: bytes, addr: Addr, now_s: float, row: tm.Row,
                       remembered: bool = False) -> None:
        """Decode, verify and dispatch a datagram the gate let through; never raises.
        `remembered`: its sender is already remembered for this datagram (its head)."""
        decoded = decode_datagram(self.rx_codec, data)
        if decoded.bad:
            self.counters["bad_packets"] += decoded.bad
        if decoded.unknown:  # a bigger dialect's types (ardupilotmega...): not garbage
            self.counters["unknown_types"] += decoded.unknown
        messages = [m for m in decoded.messages
                    if signature_ok(self.verifier, m, self.counters)]
        signed = self.verifier is not None
        if not remembered and messages and (
                not signed or any(m._header.incompat_flags & IFLAG_SIGNED for m in messages)):
            self._remember(addr, now_s)
        rx = Rx(addr, now_s, row)
        for msg in messages:
            self.dispatch(msg, rx)

    def dispatch(self, msg: Msg, rx: Rx) -> str:
        """Handle one message inside its own error boundary; returns and counts its outcome."""
        kind = msg.get_type()
        try:
            outcome = self._route(kind, msg, rx)
        except Exception:  # a bug or a hostile value: count it, answer it, keep flying
            outcome = "failed"
            self._failed(kind, msg, rx)
        self.messages[f"{kind}:{outcome}"] += 1
        return outcome

    def _failed(self, kind: str, msg: Msg | None, rx: Rx) -> None:
        """A handler raised (called from its `except`): counted, logged, answered."""
        self.counters["handler_errors"] += 1
        if self.counters["handler_errors"] <= MAX_LOGGED_ERRORS:
            log.exception("vehicle %d: %s handler failed", self.sysid, kind)
        self._answer_failure(kind, msg, rx)

    def _route(self, kind: str, msg: Msg, rx: Rx) -> str:
        service = self.handlers.get(kind)
        if service is not None:
            return service(msg, rx.addr)
        handler = HANDLERS.get(kind)
        if handler is None:
            return "ignored" if kind in IGNORED else "unhandled"
        if self._other_system(getattr(msg, "target_system", 0)):
            return "ignored"
        return handler(self, msg, rx)

    def _other_system(self, target_system: int) -> bool:
        """A message addressed to another system (0 is everyone): counted, not handled."""
        if target_system in (0, self.sysid):
            return False
        self.counters["ignored_other_sysid"] += 1
        return True

    def _answer_failure(self, kind: str, msg: Msg | None, rx: Rx) -> None:
        try:
            if msg is not None and kind in ("COMMAND_LONG", "COMMAND_INT"):
                ack = self.mav.command_ack_encode(msg.command, 4, 0, 0, msg.get_srcSystem(),
                                                  msg.get_srcComponent())
                self.send_to(encode(self.mav, ack), rx.addr)
            self.send_to(self.statustext(SEVERITY_WARNING, f"{kind} failed"), rx.addr)
        except Exception:  # the answer itself failed: the count above is all we can do
            self.counters["answer_errors"] += 1

    def _remember(self, addr: Addr, now_s: float) -> None:
        """The sender of a datagram that carried messages (signed ones, when signing is
        enforced) as a peer (sim_backend.peers)."""
        if self.verifier is None:
            self.peers.remember(addr, now_s)
        elif not self.peers.remember_signed(addr, now_s):
            self.counters["peers_refused"] += 1

    # ---- send ---------------------------------------------------------------------------
    def build(self, msg_id: int, row: tm.Row) -> bytes | None:
        """One packed message of id msg_id describing `row`, or None if not produced here."""
        if msg_id in tm.FAST_IDS:  # streamed at the control rate: no packer made for it
            return tm.fast_bytes(self.mav, msg_id, row, self.home)
        pack = self.packer(msg_id, row)
        return None if pack is None else pack()

    def packer(self, msg_id: int, row: tm.Row) -> Callable[[], bytes] | None:
        """What packs that message when called, or None: a command's reply is packed after
        its ACK, so that its signing timestamp and sequence number follow the ACK's (a
        verifying receiver drops a frame stamped before one it has seen: a replay)."""
        if msg_id in tm.FAST_IDS:
            return lambda: tm.fast_bytes(self.mav, msg_id, row, self.home)
        if msg_id == tm.MSG_PROTOCOL_VERSION:
            return lambda: tm.protocol_version(self.mav)
        if msg_id not in tm.STATUS_IDS:
            return None
        ap = self.autopilot
        flavour, mode, armed, home_ned_m = ap.flavour, ap.mode, ap.armed, ap.home_ned_m
        return lambda: tm.status_bytes(self.mav, msg_id, row, self.home, flavour, mode, armed,
                                       self.sysid, home_ned_m) or b""

    def statustext(self, severity: int, text: str) -> bytes:
        msg = self.mav.statustext_encode(severity, text.encode()[:50])
        return encode(self.mav, msg)

    def telemetry(self, now_s: float, row: tm.Row) -> None:
        """Send every stream that is due at sim time `now_s`, as one datagram per destination."""
        out = b""
        ap = self.autopilot
        if (ap.mode, ap.armed) != self._announced:
            # Announce mode and arming changes at once so clients need not wait up to 1 s.
            self._announced = (ap.mode, ap.armed)
            self.next_due[tm.MSG_HEARTBEAT] = now_s
        while ap.notices:
            severity, text = ap.notices.pop(0)
            out += self.statustext(severity, text)
        next_due, late_s = self.next_due, now_s + 1e-6
        for msg_id, interval in self.intervals.items():
            # 1 us of slack: summed float periods (0.1 + 0.02 > 0.12) must not skip a tick.
            if interval <= 0.0 or late_s < next_due[msg_id]:
                continue
            due = next_due[msg_id] + interval
            next_due[msg_id] = due if due > now_s else now_s + interval
            data = tm.fast_bytes(self.mav, msg_id, row, self.home) if msg_id in tm.FAST_IDS \
                else self.build(msg_id, row)
            if data is not None:
                out += data
        if out:
            self.broadcast(out, now_s)

    def broadcast(self, data: bytes, now_s: float) -> None:
        peers = self.peers
        if peers:
            peers.expire(now_s)
        self.send_to(data, self.default_dest)
        for addr in peers:
            if addr != self.default_dest:
                self.send_to(data, addr)

    def send_to(self, data: bytes, addr: Addr) -> None:
        try:
            self.sock.sendto(data, addr)
            self.counters["tx_datagrams"] += 1
        except ConnectionRefusedError:  # a connected vehicle's agent not (yet) listening
            self.counters["peer_unreachable"] += 1
        except OSError:
            self.counters["tx_errors"] += 1


def _heartbeat(ep: EndpointView, msg: Msg, rx: Rx) -> str:
    return "handled"  # a GCS's heartbeat only keeps it in `peers` (done on receipt)


# The one dispatch table: message type -> handler returning the outcome.
HANDLERS: dict[str, Handler] = {
    "HEARTBEAT": _heartbeat,
    SETPOINT_KIND: commands.on_setpoint,
    "COMMAND_LONG": commands.on_command,
    "COMMAND_INT": commands.on_command,
    **protocols.HANDLERS,
}
# Types received from ground stations that need no answer and change nothing here.
IGNORED = frozenset({
    "COMMAND_ACK", "STATUSTEXT", "MANUAL_CONTROL", "RC_CHANNELS_OVERRIDE", "PARAM_VALUE",
    "PARAM_EXT_REQUEST_LIST", "PARAM_EXT_REQUEST_READ", "PARAM_EXT_SET", "GPS_RTCM_DATA",
    "MISSION_ITEM_REACHED", "MISSION_CURRENT", "AUTOPILOT_VERSION",
})
