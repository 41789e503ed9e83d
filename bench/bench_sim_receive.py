"""Throughput of the simulator's receive path (issue #11): messages handled per second.

Feeds random and structured MAVLink 2 messages of every handled type (the fuzz test's mix)
straight into one in-process vehicle endpoint, no UDP, and prints messages per second and
the outcome counts.  Replies go to the discard port.

Run: python bench/bench_sim_receive.py [--messages 50000]
"""

from __future__ import annotations

import argparse
import time

from agents.scenario.model import HomeConfig, VehicleConfig
from sim_backend.runtime import SimConfig, Simulator, grid_spawn_ned
from tests.integration.test_sim_fuzz import PER_DATAGRAM, Fuzzer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--messages", type=int, default=50_000)
    args = parser.parse_args()
    sim = Simulator(grid_spawn_ned(1), VehicleConfig(), HomeConfig(),
                    SimConfig(listen_base_port=0, send_base_port=9))
    fuzzer = Fuzzer(seed=11)
    datagrams = [fuzzer.datagram()[0] for _ in range(args.messages // PER_DATAGRAM)]
    ep = sim.endpoints[0]
    start = time.perf_counter()
    for data in datagrams:
        ep.on_datagram(data, ("127.0.0.1", 9), sim.sim_time_s, sim._rows[0])
    wall = time.perf_counter() - start
    sim.close()
    n = len(datagrams) * PER_DATAGRAM
    print(f"{n} messages in {wall:.2f} s: {n / wall:,.0f} msg/s on one core "
          f"({sim.counters['commands']} commands, {sim.counters['bad_packets']} bad frames, "
          f"handler_errors={sim.counters['handler_errors']})")
    outcomes: dict[str, int] = {}
    for key, count in sim.messages.items():
        outcome = key.split(":")[1]
        outcomes[outcome] = outcomes.get(outcome, 0) + count
    print("outcomes:", outcomes)


if __name__ == "__main__":
    main()
