"""A target process: flies target vehicle j along its scenario profile through the MAVLink adapter.

    python -m agents.target --index J --scenario paper --swarm S --connect tcp/127.0.0.1:P

Until the start stamp it holds its start point at rest; afterwards it tracks the
profile with feed-forward velocity and a proportional position correction.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
from collections.abc import Sequence

import numpy as np

from agents.mavlink.adapter import MavlinkAdapter
from agents.mavlink.vehicle import Vehicle
from agents.scenario.model import Scenario
from agents.scenario.target_motion import TargetMotion
from agents.shell.process import StatusReporter, load_run_scenario, process_main
from agents.shell.process_options import AgentOptions, add_bus_arguments, add_vehicle_arguments
from agents.shell.tick_cost import NoCost, TickCost
from agents.shell.vehicle_loop import fly
from errors import EncloseError
from transport.access import sender_ids
from transport.bus import Bus
from transport.decoder import Decoder
from transport.key_exprs import SwarmKeys
from transport.message_checks import DEFAULT_LIMITS
from transport.messages import RunControl

log = logging.getLogger("enclose.target")
POSITION_GAIN_PER_S = 1.0
ALTITUDE_GAIN_PER_S = 1.0


def tracking_command(
    ref_pos_m: np.ndarray, ref_vel_m_s: np.ndarray, pos_m: np.ndarray, speed_max_m_s: float
) -> np.ndarray:
    """Feed-forward plus proportional correction, bounded by the vehicle's speed."""
    u = ref_vel_m_s + POSITION_GAIN_PER_S * (ref_pos_m - pos_m)
    speed = float(np.hypot(*u))
    return u if speed <= speed_max_m_s else u * (speed_max_m_s / speed)


def reference(
    motion: TargetMotion, index: int, start_s: float | None, now_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Target `index`'s (2,) profile position and velocity at `now_s`; before the start (no
    start word yet, or the word heard ahead of its start stamp), its start point at rest.

    The profile's velocity at t = 0 is not zero.  Fed forward while waiting, it held the
    target v / POSITION_GAIN_PER_S (1 m at 1 m/s) ahead of its start point, and set it
    off at the word, a start delay early: the run began with the targets displaced."""
    if start_s is None or now_s < start_s:
        pos, vel = motion.state_of(index, 0.0)
        return pos, np.zeros_like(vel)
    return motion.state_of(index, now_s - start_s)


class TargetNode:
    def __init__(
        self, scenario: Scenario, index: int, bus: Bus, vehicle: Vehicle, swarm: str
    ) -> None:
        self.index, self.bus, self.vehicle = index, bus, vehicle
        self.motion = TargetMotion(scenario, horizon_s=scenario.run.duration_s + 60.0)
        self.altitude_m = scenario.vehicle.altitude_m
        self.speed_max_m_s = scenario.vehicle.max_speed_xy_m_s
        self.keys = SwarmKeys(swarm)
        self.control = bus.subscribe(self.keys.control())
        self.decoder = Decoder(expect=(RunControl,), limits=DEFAULT_LIMITS,
                               senders=sender_ids(scenario.n, scenario.m))
        self.status = StatusReporter(bus, self.keys, "target", index)
        self.cost: TickCost | NoCost = NoCost()  # set by the loop (agents.shell.tick_cost)
        self.start_s: float | None = None
        self.stop_s = math.inf

    def tick(self, now_s: float) -> None:
        for inbound in self.decoder.drain(self.control):
            msg = inbound.message
            if isinstance(msg, RunControl) and msg.command == "start":
                self.start_s, self.stop_s = msg.start_stamp_s, msg.start_stamp_s + msg.duration_s
            elif isinstance(msg, RunControl):
                self.stop_s = min(self.stop_s, now_s)
        self.cost.mark("receive")
        state = self.vehicle.poll()
        self.cost.mark("mav_in")
        ref_pos, ref_vel = reference(self.motion, self.index, self.start_s, now_s)
        pos = np.asarray(state.pos_enu_m)
        if not state.link_ok or not np.all(np.isfinite(pos)):
            self.status.counters["ticks_without_vehicle"] += 1
            return
        u = tracking_command(ref_pos, ref_vel, pos[:2], self.speed_max_m_s)
        climb = ALTITUDE_GAIN_PER_S * (self.altitude_m - pos[2])
        self.cost.mark("law")
        if not self.vehicle.send_velocity_enu((float(u[0]), float(u[1]), float(climb))):
            self.status.counters["setpoints_refused"] += 1
        self.cost.mark("mav_out")

    def counters(self) -> dict[str, int]:
        return {**self.decoder.counters(), **self.cost.counters()}

    def close(self) -> None:
        self.control.close()


def run(opts: AgentOptions) -> int:
    scenario = load_run_scenario(opts.bus)
    if not 0 <= opts.index < scenario.m:
        raise EncloseError(f"--index must be within 0..{scenario.m - 1}")

    def make(bus: Bus, mav: MavlinkAdapter) -> TargetNode:
        return TargetNode(scenario, opts.index, bus, mav, opts.bus.swarm)

    return fly(opts, scenario, "target", scenario.n + opts.index, make)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="enclose-target", description=__doc__)
    add_bus_arguments(parser)
    parser.add_argument("--index", type=int, required=True, help="target number, 0-based")
    add_vehicle_arguments(parser)
    return process_main(parser, argv, AgentOptions.from_namespace, run,
                        lambda o: f"target-{o.index}")


if __name__ == "__main__":
    sys.exit(main())
