"""What a flood of unsigned-HEARTBEAT-prefixed datagrams costs a signing vehicle per tick
(issue 51, item 6): an 8-byte MAVLink 1 HEARTBEAT header (id 0, accepted unsigned, its CRC
not checked by the screen) in front of 12-byte frames that each fail their CRC, at every
size; the vehicle reads what its tick's budget allows (agents.mavlink.rx_gate).
`uncut`: the whole datagram parsed, as before; `cut`: the prefix's frame alone.

    PYTHONPATH=. python bench/bench_heartbeat_prefix.py
"""

from __future__ import annotations

import time
from collections.abc import Callable

from agents.mavlink import rx_gate
from agents.scenario.model import HomeConfig, VehicleConfig
from sim_backend.runtime import SimConfig, Simulator, grid_spawn_ned

SECRET = bytes(range(7, 39))
PREFIX = b"\xfe\x09\x00\x01\x01\x00" + b"\x00" * 11  # MAVLink 1 HEARTBEAT, a bad CRC
FAKE = b"\xfd\x00\x00\x00\x01\x01\x00\x00\x00\x00\x00\x00"  # 12 bytes of v2 HEARTBEAT
TICKS = 200


def tick_cost_us(cut: bool, size: int) -> tuple[float, int]:
    """CPU per vehicle-tick, and datagrams taken per tick, under a flood of `size` bytes."""
    sim = Simulator(grid_spawn_ned(1), VehicleConfig(), HomeConfig(),
                    SimConfig(listen_base_port=0, send_base_port=9, signing_secret=SECRET))
    ep, row = sim.endpoints[0], sim._rows[0]
    data = (PREFIX + FAKE * (size // len(FAKE)))[:size]
    head: Callable[[bytes], int | None] = rx_gate.unsigned_head
    if not cut:
        rx_gate.unsigned_head = lambda _d: None  # type: ignore[assignment]
    taken, t0 = 0, time.process_time()
    try:
        for _ in range(TICKS):
            carried = ep.gate.new_tick()
            if carried is not None:
                ep.parse_datagram(carried[0], ("127.0.0.2", 5), 0.0, row)
                taken += 1
            while ep.gate.open:  # what the simulator reads of a flooded port in a tick
                ep.on_datagram(data, ("127.0.0.2", 5), 0.0, row)
                taken += 1
    finally:
        rx_gate.unsigned_head = head  # type: ignore[assignment]
        sim.close()
    return (time.process_time() - t0) / TICKS * 1e6, taken // TICKS


def main() -> None:
    for size in (300, 1000, 8000):
        for cut in (False, True):
            us, n = min(tick_cost_us(cut, size) for _ in range(3))
            print(f"{size:5d} B  {'cut  ' if cut else 'uncut'}  {us:7.0f} us per vehicle-tick"
                  f"  ({n} datagrams a tick)")


if __name__ == "__main__":
    main()
