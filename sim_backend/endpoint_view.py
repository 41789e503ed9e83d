"""What a message handler sees of its vehicle's endpoint (sim_backend.endpoint): a narrow
protocol, so that the handlers (sim_backend.commands, sim_backend.protocols) are imported
by the endpoint and import nothing of it.

Handlers take (endpoint, message, rx) and return the outcome the endpoint counts.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

from agents.mavlink.rx_gate import Addr
from agents.mavlink.wire_decode import Codec
from agents.mavlink.wire_decode import MAVLinkMessage as Msg
from agents.scenario.model import HomeConfig
from sim_backend import telemetry as tm
from sim_backend.autopilot import Autopilot
from sim_backend.params import ParamStore

# frame, command, current, autocontinue, param1..4, x (degE7), y (degE7), z
Item = tuple[int, int, int, int, float, float, float, float, int, int, float]


class Rx(NamedTuple):
    """Where and when one message arrived, and the vehicle's state at that tick (made for
    every datagram: a named tuple is several times cheaper than a frozen dataclass)."""

    addr: Addr
    now_s: float
    row: tm.Row


@dataclass
class MissionStore:
    """The stored mission (type 0 only) and an upload in progress."""

    items: list[Item] = field(default_factory=list)
    upload: list[Item] | None = None
    upload_count: int = 0


class EndpointView(Protocol):
    """One simulated vehicle's endpoint, as its handlers use it: its autopilot, parameters,
    home, missions and streams, its counters, and how to pack and send a reply."""

    @property
    def autopilot(self) -> Autopilot: ...
    @property
    def params(self) -> ParamStore: ...
    @property
    def home(self) -> HomeConfig: ...
    @property
    def missions(self) -> MissionStore: ...
    @property
    def counters(self) -> Counter[str]: ...
    @property
    def mav(self) -> Codec: ...
    @property
    def default_intervals(self) -> dict[int, float]: ...
    @property
    def intervals(self) -> dict[int, float]: ...
    @property
    def next_due(self) -> dict[int, float]: ...

    def packer(self, msg_id: int, row: tm.Row) -> Callable[[], bytes] | None: ...
    def statustext(self, severity: int, text: str) -> bytes: ...
    def send_to(self, data: bytes, addr: Addr) -> None: ...


Handler = Callable[[EndpointView, Msg, Rx], str]
