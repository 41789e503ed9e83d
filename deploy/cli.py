"""`enclose` console script: wires subcommands, turns named errors into exit codes."""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from agents.shell.lifeline import die_with_launcher
from agents.shell.phases import mark
from enclose_release import VERSION
from errors import EncloseError

# Each module exposes `register(subparsers)`, which adds its subparser and sets `func(args) -> int`.
# Keyed by the command it registers: `enclose run` imports only deploy.commands.run (not the
# plotting and lock-step modules of the others: ~1.5 s of imports before the swarm starts).
COMMANDS: dict[str, str] = {
    "simulate": "deploy.commands.simulate",
    "run": "deploy.commands.run",
    "report": "deploy.report.run_report",
    "sim": "deploy.commands.sim",
    "sweep": "deploy.sweep.command",
    "keys": "deploy.commands.keys",
    "vehicle-key": "deploy.commands.vehicle_key",
    "host": "deploy.commands.host",
    "replay": "deploy.commands.replay",
}
COMMAND_MODULES: tuple[str, ...] = tuple(COMMANDS.values())


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The parser; given the command line, with only the subcommand it names (if any)."""
    parser = argparse.ArgumentParser(
        prog="enclose",
        description="Finite-time enclosing of moving targets by a networked swarm.",
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    parser.add_argument("--version", action="version", version=f"enclose {VERSION}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    first = next((a for a in argv or () if not a.startswith("-")), None)
    for name in (COMMANDS[first],) if first in COMMANDS else COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    die_with_launcher()  # an inner launcher (deploy.netns.netns_run) dies with the outer one
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser(argv).parse_args(argv)
    mark("imports")  # the subcommand's module is imported
    level = logging.WARNING - 10 * min(args.verbose, 2) + 10 * 0
    logging.basicConfig(
        level=min(level, logging.INFO) if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.func(args))
    except EncloseError as exc:
        logging.getLogger("enclose").error("%s: %s", type(exc).__name__, exc)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
