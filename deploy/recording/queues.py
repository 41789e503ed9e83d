"""The recorder's queues: one Zenoh ring per recorded key, sized to its traffic, emptied
in pieces on every step (deploy.recording.intake records them at once)."""

from __future__ import annotations

import math
from collections.abc import Iterator

from agents.scenario.model import Scenario
from transport.bus import Received, Subscription
from transport.key_exprs import SwarmKeys

# Each queue as long as its key's traffic fills in this time (at most QUEUE_MAX): all the
# backlog a stall or an insider's flood may need, and its ring's pages mapped early on.
QUEUE_HOLD_S = 120.0
QUEUE_MIN, QUEUE_MAX = 256, 16384
# A ring is emptied a piece at a time (few unpacked samples alive at once), at most a
# full ring's worth a step however fast a flood refills it meanwhile.
DRAIN_PIECE = 1024
DRAIN_PIECES_MAX = QUEUE_MAX // DRAIN_PIECE + 1


def queue_capacities(keys: SwarmKeys, scenario: Scenario, sensor: bool) -> dict[str, int]:
    """Each recorded key's queue, sized to QUEUE_HOLD_S of its traffic.

    Not one size for all: Zenoh allocates a ring's whole capacity up front and the kernel
    maps its pages as the write position first passes them, so a ring far larger than its
    key's traffic reads as memory creeping up for as long as one lap takes: the statuses'
    16384 slots at ~9 a second took 30 minutes of the paper's case, +4 MB."""
    n, hz = scenario.n, scenario.run.rate_hz
    # Truth and observations go out every simulator tick that gives at least the control
    # rate (sim_backend.swarm_sim), under twice it: their rings fill in at most QUEUE_HOLD_S.
    # Every process's status once a second.
    per_s = {keys.all_follower_states(): n * hz, keys.all_sensor_targets(): n * hz,
             keys.truth(): hz, keys.all_status(): n + scenario.m + 4.0}
    return {k: _ring_size(per_s.get(k, 1.0) * QUEUE_HOLD_S) for k in keys.recorded(sensor)}


def _ring_size(items: float) -> int:
    return min(QUEUE_MAX, max(QUEUE_MIN, math.ceil(items)))


def drain_pieces(sub: Subscription) -> Iterator[list[Received]]:
    """`sub`'s ring emptied in pieces of DRAIN_PIECE, at most a full ring's worth."""
    for _ in range(DRAIN_PIECES_MAX):
        piece = sub.drain(DRAIN_PIECE)
        yield piece
        if len(piece) < DRAIN_PIECE:
            break
