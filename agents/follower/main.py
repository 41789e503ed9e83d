"""A follower process: its vehicle through MAVLink, its peers through the bus, one loop.

python -m agents.follower.main --index I --scenario paper --swarm S --connect tcp/127.0.0.1:P
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from agents.follower.journal import JournalWriter, journal_path
from agents.follower.node import FollowerNode
from agents.mavlink.adapter import MavlinkAdapter
from agents.shell.network_args import network_overrides
from agents.shell.process import load_run_scenario, process_main
from agents.shell.process_options import AgentOptions, add_bus_arguments, add_vehicle_arguments
from agents.shell.vehicle_loop import fly
from errors import EncloseError
from transport.bus import Bus
from transport.impairment import ImpairedBus


# The node (its state and loop body) is agents.follower.node, not named in the module
# docstring above: that is this process's --help text.
def run(opts: AgentOptions) -> int:
    # The launcher (or the user's `enclose` command) checked the targets' spread over the
    # whole run; that check needs numpy, which this process never imports (issue 15).
    scenario = load_run_scenario(opts.bus, whole_run=False)
    if not 0 <= opts.index < scenario.n:
        raise EncloseError(f"--index must be within 0..{scenario.n - 1}")

    def make(bus: Bus, mav: MavlinkAdapter) -> FollowerNode:
        impaired = ImpairedBus(bus, scenario.network, receiver=opts.index)  # [network] links
        node = FollowerNode(scenario, opts.index, impaired, mav, opts.bus.swarm, opts.join)
        node.liar.install()  # the launcher's `lie` fault arrives as a signal
        if opts.journal is not None:
            node.runner.journal = JournalWriter(journal_path(Path(opts.journal), opts.index),
                                                journal_header(opts),
                                                node.runner.declared)
        return node

    return fly(opts, scenario, "follower", opts.index, make)


def journal_header(opts: AgentOptions) -> dict[str, object]:
    """What `enclose replay` needs besides the records: who, and the run's law."""
    scen = opts.bus.scenario
    if scen is not None and scen.endswith(".toml"):
        scen = str(Path(scen).resolve())
    return {"index": opts.index, "scenario": scen, "law": opts.bus.law.law,
            "law_params": [list(p) for p in opts.bus.law.params],
            "network": network_overrides(opts.bus.network)}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="enclose-follower", description=__doc__)
    add_bus_arguments(parser)
    parser.add_argument("--index", type=int, required=True, help="follower number, 0-based")
    parser.add_argument("--join", action="store_true",
                        help="the swarm is already running (a restart): start from the "
                             "neighbours' estimate, not from p~")
    parser.add_argument("--journal", default=None, metavar="DIR",
                        help="journal every input of the law into DIR/follower-I.journal "
                             "(enclose replay)")
    add_vehicle_arguments(parser)
    return process_main(parser, argv, AgentOptions.from_namespace, run,
                        lambda o: f"follower-{o.index}")


if __name__ == "__main__":
    sys.exit(main())
