"""Each process's latest status on the bus, as the launcher holds it during a run: the
data of its board (deploy.launch.run_monitor) and the final counters of launch.json."""

from __future__ import annotations

from collections.abc import Collection
from typing import Any

from transport.bus import Subscription
from transport.decoder import Decoder
from transport.message_checks import DEFAULT_LIMITS
from transport.messages import ProcessStatus


class StatusBoard:
    """Each process's latest ProcessStatus (its final counters go to launch.json).

    A status counts only from the process it names, on its own key (transport.message_checks):
    the table holds at most one entry per sender of the scenario (`senders`)."""

    def __init__(self, senders: Collection[str]) -> None:
        self.subscription: Subscription | None = None
        self.latest: dict[str, ProcessStatus] = {}
        self.decoder = Decoder(expect=(ProcessStatus,), limits=DEFAULT_LIMITS, senders=senders)

    def collect(self) -> None:
        if self.subscription is None:
            return
        for inbound in self.decoder.drain(self.subscription):
            msg = inbound.message
            if isinstance(msg, ProcessStatus):
                self.latest[f"{msg.role}-{msg.index}"] = msg

    def state_of(self, name: str) -> str:
        status = self.latest.get(name)
        return "" if status is None else status.state

    def as_dict(self) -> dict[str, Any]:
        return {name: {"state": s.state, **s.counters} for name, s in self.latest.items()}
