"""A follower process: its vehicle through MAVLink, its peers through the bus, one loop.

python -m agents.follower --index I --scenario paper --swarm S --connect tcp/127.0.0.1:P
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from agents.follower_node import FollowerNode
from agents.mavlink.adapter import MavlinkAdapter
from agents.process import add_bus_arguments, load_run_scenario, process_main
from agents.vehicle_loop import add_vehicle_arguments, fly
from transport.bus import Bus
from transport.errors import EncloseError
from transport.impairment import ImpairedBus


# The node (its state and loop body) is agents.follower_node, not named in the module
# docstring above: that is this process's --help text.
def run(args: argparse.Namespace) -> int:
    scenario = load_run_scenario(args)
    if not 0 <= args.index < scenario.n:
        raise EncloseError(f"--index must be within 0..{scenario.n - 1}")

    def make(bus: Bus, mav: MavlinkAdapter) -> FollowerNode:
        impaired = ImpairedBus(bus, scenario.network, receiver=args.index)  # [network] links
        return FollowerNode(scenario, args.index, impaired, mav, args.swarm, args.join)

    return fly(args, scenario, "follower", args.index, args.index, make)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="enclose-follower", description=__doc__)
    add_bus_arguments(parser)
    parser.add_argument("--index", type=int, required=True, help="follower number, 0-based")
    parser.add_argument("--join", action="store_true",
                        help="the swarm is already running (a restart): start from the "
                             "neighbours' estimate, not from p~")
    add_vehicle_arguments(parser)
    # The launcher (or the user's `enclose` command) checked the targets' spread over the
    # whole run; that check needs numpy, which this process never imports (issue 15).
    parser.set_defaults(whole_run_checks=False)
    return process_main(parser, argv, run, lambda a: f"follower-{a.index}")


if __name__ == "__main__":
    sys.exit(main())
