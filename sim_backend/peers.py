"""A simulated vehicle's peers: the addresses that talked to it recently, which get its
streamed telemetry besides the PX4-SITL-style default destination.

A vehicle that enforces signing takes as a peer only an address that sent it a frame
signed with its key (`remember_signed`): an unsigned HEARTBEAT (accepted, as on PX4) buys
no telemetry, and a full table refuses a newcomer rather than evict a live peer.  Without
signing, any sender is a peer and a newcomer evicts the stalest (`remember`, as PX4 SITL).
A peer silent for PEER_TIMEOUT_S is dropped (`expire`).
"""

from __future__ import annotations

from agents.mavlink.rx_gate import Addr

PEER_TIMEOUT_S = 30.0
MAX_PEERS = 8


class Peers(dict[Addr, float]):
    """Address -> when it was last heard (the vehicle's boot clock, s)."""

    def remember(self, addr: Addr, now_s: float) -> None:
        if addr not in self and len(self) >= MAX_PEERS:
            del self[min(self, key=self.__getitem__)]
        self[addr] = now_s

    def remember_signed(self, addr: Addr, now_s: float) -> bool:
        """A signed sender as a peer; False when refused: a full table makes room only from
        a peer silent for PEER_TIMEOUT_S (it would have been dropped at the next telemetry)."""
        if addr not in self and len(self) >= MAX_PEERS:
            stale = min(self, key=self.__getitem__)
            if now_s - self[stale] <= PEER_TIMEOUT_S:
                return False
            del self[stale]
        self[addr] = now_s
        return True

    def expire(self, now_s: float) -> None:
        for addr in [a for a, t in self.items() if now_s - t > PEER_TIMEOUT_S]:
            del self[addr]
